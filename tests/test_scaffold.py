"""`miro new`: every pattern scaffolds into a fresh project, passes ruff and mypy --strict, and its
own test passes against a naming service; `miro run` starts a service; bad names are refused."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from loopback import NamingProcess
from miro_cli import REPO

PATTERNS = ["basic", "server", "client", "publisher", "subscriber", "device", "timed"]
THERMO = """
module Lab
{
  struct Reading { double celsius; string unit; sequence<long> history; };
  enum Mode { OFF, ON, AUTO };
  exception Broken { string why; };
  interface Thermometer
  {
    Reading read();
    void setMode(in Mode m);
    Mode getMode();
    void calibrate(in double offset, out double previous) raises (Broken);
    string name(in string prefix, inout long count);
  };
};
"""
RUFF_CONFIG = """
[tool.ruff]
line-length = 100
target-version = "py311"

[tool.ruff.lint]
select = ["E", "F", "W", "I", "B", "UP", "SIM", "RUF"]
ignore = ["RUF012"]
"""


def env() -> dict[str, str]:
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(REPO / "generated"), str(REPO)])
    return e


def miro(project: Path, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", *args],
        cwd=project,
        env=env(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def tool(name: str) -> str:
    path = shutil.which(name) or str(Path(sys.executable).with_name(name))
    if not Path(path).exists():
        pytest.skip(f"{name} is not installed")
    return path


@pytest.fixture(scope="module")
def project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh project with a service of every pattern, two of them on the user's own IDL."""
    root = tmp_path_factory.mktemp("project")
    (root / "pyproject.toml").write_text(RUFF_CONFIG)
    (root / "idl").mkdir()
    (root / "idl" / "Thermo.idl").write_text(THERMO)
    for pattern in PATTERNS:
        made = miro(root, "new", f"my_{pattern}", "--pattern", pattern)
        assert made.returncode == 0, made.stderr
        assert f"wrote services/my_{pattern}/__main__.py" in made.stdout
        assert f"miro run my_{pattern}" in made.stdout  # the next steps
    lab = ("--idl", "idl/Thermo.idl", "--interface", "Lab::Thermometer")
    made = miro(root, "new", "thermo", "--pattern", "server", *lab)
    assert made.returncode == 0, made.stderr
    made = miro(
        root, "new", "thermo_client", "--pattern", "client", "--interface", "Lab::Thermometer"
    )
    assert made.returncode == 0, made.stderr
    return root


def test_the_scaffolds_pass_ruff(project: Path) -> None:
    for args in (
        ["check", "--no-cache", "services"],
        ["format", "--check", "--no-cache", "services"],
    ):
        done = subprocess.run([tool("ruff"), *args], cwd=project, capture_output=True, text=True)
        assert done.returncode == 0, done.stdout + done.stderr


def test_the_scaffolds_pass_mypy_strict(project: Path) -> None:
    mypy_path = os.pathsep.join([str(project / "generated"), str(REPO), str(REPO / "generated")])
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--explicit-package-bases", "--cache-dir",
         str(project / ".mypy_cache"), "services", "generated"],
        cwd=project,
        env=dict(env(), MYPYPATH=mypy_path),
        capture_output=True,
        text=True,
        timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_scaffolded_tests_pass(project: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "services"],
        cwd=project,
        env=env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "9 passed" in done.stdout


def test_the_server_on_the_users_idl_implements_every_operation(project: Path) -> None:
    implementation = (project / "services" / "thermo" / "implementation.py").read_text()
    for signature in (
        "def read(self) -> Lab.Reading:",
        "def setMode(self, m: Lab.Mode) -> None:",
        "def calibrate(self, offset: float) -> float:",
        "def name(self, prefix: str, count: int) -> tuple[str, int]:",
    ):
        assert signature in implementation


def test_miro_run_starts_a_service_against_a_real_naming_service(project: Path) -> None:
    naming = NamingProcess()
    try:
        service = subprocess.Popen(
            [sys.executable, "-m", "miro_gen.cli.main", "run", "my_basic", "--naming",
             naming.endpoint],
            cwd=project,
            env=env(),
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert service.stdout is not None
        assert service.stdout.readline().strip() == "Hello from my_basic"
        service.send_signal(signal.SIGINT)
        assert service.wait(20) == 0
        assert "my_basic: stopped" in service.stdout.read()
    finally:
        naming.stop()


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("GpsLogger", "is not a service name"),
        ("1gps", "is not a service name"),
        ("class", "is not a service name"),
        ("gps__logger", "is not a service name"),
        ("a_name_that_is_far_too_long", "at most 20 characters"),
        ("my_basic", "exists already: nothing was written"),
    ],
)
def test_bad_names_are_refused(project: Path, name: str, message: str) -> None:
    before = sorted(p.name for p in (project / "services").iterdir())
    done = miro(project, "new", name)
    assert done.returncode == 1
    assert message in done.stderr and "Traceback" not in done.stderr
    assert sorted(p.name for p in (project / "services").iterdir()) == before


def test_an_unknown_interface_is_refused(project: Path) -> None:
    done = miro(project, "new", "nowhere", "--pattern", "server", "--interface", "Lab::Missing")
    assert done.returncode == 1
    assert "no generated code for interface Lab::Missing" in done.stderr
    assert not (project / "services" / "nowhere").exists()
