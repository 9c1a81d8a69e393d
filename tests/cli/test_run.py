"""`miro run NAME` starts every shipped service (a single file, or a package such as the
drivers) exactly as `python services/NAME` does, in its own interpreter, from any folder:
the same usage for --help, the same status, no traceback; names that are not there are
explained."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from loopback import free_port, service_env
from miro_cli import REPO

SERVICES = REPO / "services"
SHIPPED = sorted(
    p.stem if p.suffix == ".py" else p.name
    for p in SERVICES.iterdir()
    if p.suffix == ".py" or (p / "__main__.py").is_file()
)


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        args, cwd=cwd, capture_output=True, text=True, env=service_env(), timeout=120
    )


def test_the_shipped_services_are_found() -> None:
    assert {"exampleA", "exampleD", "gps_position", "gps", "laser", "camera"} <= set(SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
def test_miro_run_is_python_services_name(name: str, tmp_path: Path) -> None:
    """The same help (or the same one-line refusal, for a Qt service without PySide6), and the
    same status, run either way; from a folder that is not the checkout."""
    path = SERVICES / name if (SERVICES / name).is_dir() else SERVICES / f"{name}.py"
    python = run([sys.executable, str(path), "--help"], tmp_path)
    miro = run([sys.executable, "-m", "miro_gen.cli.main", "run", name, "--help"], tmp_path)
    assert "Traceback" not in python.stderr + miro.stderr, python.stderr + miro.stderr
    assert (miro.returncode, miro.stdout, miro.stderr) == (
        python.returncode,
        python.stdout,
        python.stderr,
    )


def test_a_service_with_sibling_modules(tmp_path: Path) -> None:
    """services/gps imports its sibling nmea.py, as `python services/gps` lets it."""
    done = run([sys.executable, "-m", "miro_gen.cli.main", "run", "gps", "--help"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: gps")


def test_a_shipped_server_told_not_to_wait_for_its_naming_service(tmp_path: Path) -> None:
    naming = f"tcp://127.0.0.1:{free_port()}"
    command = ["run", "exampleA", "--naming", naming, "--wait-naming", "0"]
    done = run([sys.executable, "-m", "miro_gen.cli.main", *command], tmp_path)
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1 and "is `miro naming` running?" in done.stderr


@pytest.mark.parametrize(
    ("name", "says"),
    [
        ("Bad-Name", "'Bad-Name' is not a service name: use lower-case letters, digits and "
         "single underscores, starting with a letter (bad_name would do)"),
        ("class", "'class' is a Python keyword"),
        ("nothere", "(make one with `miro new nothere`)"),
    ],
)  # fmt: skip
def test_a_service_that_is_not_there(name: str, says: str, tmp_path: Path) -> None:
    done = run([sys.executable, "-m", "miro_gen.cli.main", "run", name], tmp_path)
    assert done.returncode == 1
    assert done.stderr.startswith(f"miro run: no service {name!r} in {tmp_path / 'services'}")
    assert says in done.stderr
    assert "there are: " in done.stderr and ", exampleA, exampleB," in done.stderr
    if name != "nothere":
        assert "miro new" not in done.stderr  # no advice that would fail in its turn
