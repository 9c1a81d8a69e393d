"""The ROS 2 peer of the tests: a virtual environment of its own with the ROS 2 Kilted wheels of
tests/ros2/requirements.txt.

The wheels never go into miro-gen's environment: rosidl_parser depends on lark-parser 0.12, whose
`lark` module replaces the lark 1.x miro-idl needs. The tests use them only through this
environment's python, in subprocesses (`Ros2Env.run_json` runs a script of tests/ros2/ there and
reads the JSON it prints), and read the interface files from its `share/` folder.

The environment is made once for each content of the requirements file (and Python version),
under a lock as several test runs may share it: at $MIRO_ROS2_VENV if set, else in the user's
cache folder ($XDG_CACHE_HOME or ~/.cache, `miro-gen/ros2-venv-<hash>`); pip's cache makes a
remake quick. .ci/run makes it before the tests (`python tests/ros2_env.py`, standard library
only), so that CI fails when it cannot; elsewhere the tests that need it are skipped, saying why
(the `ros2` fixture of tests/conftest.py gives it to a test, or skips it).
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import json
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent / "ros2"
REQUIREMENTS = HERE / "requirements.txt"
READY = ".miro-ros2-ready"  # written last, holding the digest of what was installed
INSTALL_TIMEOUT = 1800.0


class Ros2EnvUnavailable(RuntimeError):
    """The environment could not be made (the reason is the message)."""


@dataclass(frozen=True)
class Ros2Env:
    """A made ROS 2 environment: its python, its `share/` folder, and how to run in it."""

    prefix: Path

    @property
    def python(self) -> Path:
        return self.prefix / "bin" / "python"

    @property
    def share(self) -> Path:
        """Where the interface packages are (`share/<pkg>/msg/...`), an include root for
        miro-idl as for rosidl."""
        return self.prefix / "share"

    def environ(self) -> dict[str, str]:
        """The environment of a process of this ROS 2: its bin first on PATH, its prefix as the
        ament prefix, nothing of the test's Python path, discovery kept on this host."""
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
        env["PATH"] = f"{self.prefix / 'bin'}{os.pathsep}{env.get('PATH', '')}"
        env["AMENT_PREFIX_PATH"] = str(self.prefix)
        env["PYTHONNOUSERSITE"] = "1"
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        return env

    def run(
        self, *args: str, input: str | None = None, timeout: float = 300
    ) -> subprocess.CompletedProcess[str]:
        """`python ARGS` in this environment."""
        return subprocess.run(
            [str(self.python), *args],
            input=input,
            env=self.environ(),
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    def run_json(self, script: str, *args: str, input: str | None = None) -> Any:
        """What tests/ros2/SCRIPT prints as JSON, run in this environment with ARGS."""
        done = self.run(str(HERE / script), *args, input=input)
        if done.returncode != 0:
            raise AssertionError(f"{script} failed in {self.prefix}:\n{done.stderr[-4000:]}")
        return json.loads(done.stdout)


def digest() -> str:
    """What names an environment: the requirements and the Python version."""
    h = hashlib.sha256(REQUIREMENTS.read_bytes())
    h.update(f"{sys.version_info.major}.{sys.version_info.minor}".encode())
    return h.hexdigest()[:12]


def location() -> Path:
    if os.environ.get("MIRO_ROS2_VENV"):
        return Path(os.environ["MIRO_ROS2_VENV"]).resolve()
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return cache / "miro-gen" / f"ros2-venv-{digest()}"


def make(prefix: Path | None = None) -> Ros2Env:
    """The environment, made first if it is not there (or was left half made)."""
    prefix = prefix or location()
    env = Ros2Env(prefix)
    want = digest()
    ready = prefix / READY
    if ready.is_file() and ready.read_text() == want:
        return env
    prefix.parent.mkdir(parents=True, exist_ok=True)
    with open(prefix.parent / f"{prefix.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another run may be making it: wait for it
        if ready.is_file() and ready.read_text() == want:
            return env
        shutil.rmtree(prefix, ignore_errors=True)
        try:
            _install(env)
        except Ros2EnvUnavailable:
            shutil.rmtree(prefix, ignore_errors=True)
            raise
        ready.write_text(want)
    return env


def _install(env: Ros2Env) -> None:
    """A new virtual environment at `env.prefix` with the requirements, checked."""
    _step([sys.executable, "-m", "venv", str(env.prefix)], "python -m venv", 300)
    _step(
        [str(env.python), "-m", "pip", "install", "-q", "--disable-pip-version-check",
         "--retries", "3", "-r", str(REQUIREMENTS)],
        "pip install -r tests/ros2/requirements.txt",
        INSTALL_TIMEOUT,
    )  # fmt: skip
    if not (env.share / "std_msgs" / "msg" / "Header.idl").is_file():
        raise Ros2EnvUnavailable(f"{env.share} has no std_msgs/msg/Header.idl")
    _step([str(env.python), "-c", "import rosidl_parser.parser"], "import rosidl_parser", 120)


def _step(cmd: list[str], what: str, timeout: float) -> None:
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise Ros2EnvUnavailable(f"{what}: {e}") from e
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise Ros2EnvUnavailable(f"{what} failed: {last}")


@functools.cache
def available() -> tuple[Ros2Env | None, str | None]:
    """The environment, or why it cannot be made (tried once per test run)."""
    try:
        return make(), None
    except Ros2EnvUnavailable as e:
        return None, f"the ROS 2 environment of tests/ros2_env.py cannot be made: {e}"


if __name__ == "__main__":
    try:
        print(make().prefix)
    except Ros2EnvUnavailable as e:
        sys.exit(f"tests/ros2_env.py: {e}")
