"""What users install is what we test: the sdist and the wheel built from what git tracks, the
wheel's contents, and the README's quick start run from a fresh virtual environment outside
the checkout (no PYTHONPATH), then once more from a clone with the environment inside it, as the
README makes it. Every other test runs from an editable install, which reads data files from
the checkout and cannot notice one missing from the wheel (docs/PITFALLS: packaging).

Slow by nature (two builds, two environments): pip's cache keeps it to a few minutes; CI runs it
with the rest (.ci/run, the README's test command)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import venv
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest
from help_checks import check_every_help
from loopback import free_port
from miro_cli import REPO

PATTERNS = ("basic", "server", "client", "publisher", "subscriber", "device", "timed")
SHIPPED_GENERATED = ("Miro", "Miro__POA", "MiroNaming", "MiroService", "_GlobalIDL")


def tracked_files() -> list[str]:
    """The paths git tracks in this checkout, a link to a folder replaced by the tracked files
    inside it (as the link's path: miro_gen/services/exampleA.py)."""
    done = subprocess.run(
        ["git", "-C", str(REPO), "ls-files", "-s", "-z"], capture_output=True, timeout=60
    )
    if done.returncode != 0:
        pytest.skip(f"not a git checkout: {done.stderr.decode(errors='replace').strip()}")
    entries = [line.split("\t", 1) for line in done.stdout.decode().split("\0") if line]
    paths = [path for _, path in entries]
    out = []
    for info, path in entries:
        target = REPO / path
        if info.startswith("120000") and target.is_dir():
            inside = target.resolve().relative_to(REPO).as_posix() + "/"
            out += [path + "/" + p[len(inside) :] for p in paths if p.startswith(inside)]
        else:
            out.append(path)
    return sorted(out)


def copy_of_checkout(dest: Path) -> Path:
    """The tracked files of this checkout (as they are in the working tree, links kept as
    links): what a fresh clone holds, without anything the checkout's builds left."""
    listing = subprocess.run(
        ["git", "-C", str(REPO), "ls-files", "-z"], capture_output=True, check=True, timeout=60
    )
    for path in listing.stdout.decode().split("\0"):
        source = REPO / path
        if not path or not os.path.lexists(source):
            continue
        target = dest / path
        target.parent.mkdir(parents=True, exist_ok=True)
        if source.is_symlink():
            target.symlink_to(os.readlink(source))
        else:
            shutil.copy2(source, target)
    return dest


@dataclass
class Dists:
    sdist: Path
    wheel: Path
    source: Path  # the copy they were built from


@pytest.fixture(scope="module")
def dists(tmp_path_factory: pytest.TempPathFactory) -> Dists:
    """The sdist, and the wheel built from it (python -m build), of a copy of the checkout."""
    tracked_files()  # skips outside a git checkout
    source = copy_of_checkout(tmp_path_factory.mktemp("source"))
    out = tmp_path_factory.mktemp("dist")
    done = subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(out), str(source)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    (sdist,) = out.glob("*.tar.gz")
    (wheel,) = out.glob("*.whl")
    return Dists(sdist, wheel, source)


@pytest.mark.timeout(900)
def test_the_wheel_holds_every_tracked_file_under_miro_gen(dists: Dists) -> None:
    """Grammars, templates, XML, the shipped services and their data: every file git tracks
    under miro_gen/ (and in the generated packages it ships) is in the wheel."""
    names = set(zipfile.ZipFile(dists.wheel).namelist())
    wanted = [
        p
        for p in tracked_files()
        if p.startswith("miro_gen/")
        or any(p.startswith(f"generated/{package}/") for package in SHIPPED_GENERATED)
    ]
    assert len(wanted) > 300
    missing = [p for p in wanted if p.removeprefix("generated/") not in names]
    assert not missing, "missing from the wheel:\n" + "\n".join(missing)


class User:
    """A shell of a user whose virtual environment `env` is active, in folder `home`, with no
    PYTHONPATH; every command's output is kept, and none may show a traceback."""

    def __init__(self, env: Path, home: Path) -> None:
        self.env = env
        self.home = home
        home.mkdir(parents=True, exist_ok=True)
        path = [p for p in os.environ["PATH"].split(os.pathsep) if Path(p) != Path(sys.prefix)]
        path = [p for p in path if Path(p) != Path(sys.executable).parent]
        self.environ = {
            k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")
        }
        self.environ.update(
            PATH=os.pathsep.join([str(env / "bin"), *path]),
            VIRTUAL_ENV=str(env),
            MIRO_NAMING=f"tcp://127.0.0.1:{free_port()}",  # never the default port in tests
            MIRO_CACHE=str(home / ".cache-miro"),
        )
        self.environ.pop("MIRO_SERVICES", None)

    def run(self, command: str, timeout: float = 300, status: int = 0) -> str:
        """`command` (bash) in the user's folder; its output, after checking its status."""
        done = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", command],
            cwd=self.home,
            env=self.environ,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        text = done.stdout + done.stderr
        assert done.returncode == status, f"$ {command}\n{text}"
        assert "Traceback" not in text, f"$ {command}\n{text}"
        return done.stdout

    def run_until(self, command: str, line: str) -> str:
        """Start `command`, wait for `line` in its output, then Ctrl-C it: it ends quietly."""
        proc = subprocess.Popen(
            ["bash", "-c", f"exec {command}"],
            cwd=self.home,
            env=self.environ,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        seen: list[str] = []
        try:
            assert proc.stdout is not None
            for out in proc.stdout:
                seen.append(out)
                if line in out:
                    break
            proc.send_signal(signal.SIGINT)
            seen += proc.stdout.readlines()
            status = proc.wait(60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        text = "".join(seen)
        assert any(line in s for s in seen), f"$ {command}\n{text}"
        assert status in (0, 128 + signal.SIGINT), f"$ {command}: status {status}\n{text}"
        assert "Traceback" not in text, f"$ {command}\n{text}"
        return text


def fresh_env(where: Path) -> Path:
    venv.EnvBuilder(with_pip=True, clear=True).create(where)
    return where


def quick_start(user: User, install: str) -> None:
    """The README's quick start, as written (with the wheel or the clone as `install`)."""
    user.run(f"pip install -q {install}", timeout=600)
    demo = user.run("miro demo --duration 5", timeout=300)
    assert re.search(r"^exampleB +\| Retrieved variables a and b are: ", demo, re.M), demo
    assert re.search(r"^exampleC +\| ExampleEvent #\d+ published", demo, re.M), demo
    user.run("miro new hello")
    user.run("pip install -q pytest pytest-timeout", timeout=600)
    user.run("python -m pytest -q -p no:cacheprovider services/hello")
    user.run_until("miro run hello", "Hello from hello")


@pytest.mark.timeout(1800)
def test_the_quick_start_from_the_wheel_outside_the_checkout(dists: Dists, tmp_path: Path) -> None:
    user = User(fresh_env(tmp_path / "venv"), tmp_path / "work")
    quick_start(user, str(dists.wheel))
    # the compilers on the README's examples, in a project of their own: what generated/ holds
    examples = user.home / "examples"
    for folder in ("idl", "params", "generated"):
        shutil.copytree(dists.source / folder, examples / folder, symlinks=True)
    for xml in dists.source.glob("services/*/*Parameters.xml"):
        (examples / xml.relative_to(dists.source)).parent.mkdir(parents=True)
        shutil.copy2(xml, examples / xml.relative_to(dists.source))
    user.run(
        "cd examples && miro-idl -I idl --check idl/*.idl && "
        "miro-params -I idl --check params/*.xml services/*/*Parameters.xml"
    )
    # every pattern of `miro new`, with its own test
    for pattern in PATTERNS:
        user.run(f"miro new p_{pattern} --pattern {pattern}")
    user.run("python -m pytest -q -p no:cacheprovider services", timeout=600)
    check_every_help(user.run)
    user.run("miro run gps --help")


@pytest.mark.timeout(1800)
def test_the_quick_start_in_a_clone_with_its_environment_inside(tmp_path: Path) -> None:
    tracked_files()  # skips outside a git checkout
    clone = copy_of_checkout(tmp_path / "clone")
    user = User(fresh_env(clone / ".venv"), clone)
    quick_start(user, ".")
    # the project's own services and tools, beside the installed copy of them
    user.run("miro build")
    user.run("miro build --check")
    user.run("miro run gps --help")
    naming = user.environ["MIRO_NAMING"]
    server = subprocess.Popen(
        ["miro", "naming", "--endpoint", naming],
        cwd=clone,
        env=user.environ,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert server.stdout is not None and server.stdout.readline().startswith("naming service")
        user.run_until("miro run exampleA", "ExampleA is ready")
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(30)
