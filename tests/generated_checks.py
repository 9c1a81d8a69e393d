"""Checks that code miro-idl generated into a folder is product code: every module imports,
and ruff (the project's lint rules) and mypy --strict pass on it. Used by the tests that generate
outside tests/codegen/golden (the DDS dialect, real IDL trees)."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

from miro_cli import REPO

_IMPORT_ALL = """
import importlib, pkgutil, sys
failed = []
for name in sys.argv[1:]:
    try:
        package = importlib.import_module(name)
        for info in pkgutil.walk_packages(package.__path__, name + "."):
            importlib.import_module(info.name)
    except Exception as e:
        failed.append(f"{name}: {e!r}")
print("\\n".join(failed))
sys.exit(1 if failed else 0)
"""


def packages(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if (p / "__init__.py").is_file())


def import_problems(folder: Path) -> str:
    """'' when every module of every generated package imports (in a fresh interpreter)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(folder), str(REPO)]))
    out = subprocess.run(
        [sys.executable, "-c", _IMPORT_ALL, *packages(folder)],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return "" if out.returncode == 0 else out.stdout + out.stderr


def ruff_problems(folder: Path) -> str:
    """'' when ruff passes with the project's lint rules, run from the repository as for
    tests/codegen/golden (so that miro_gen is the first-party package)."""
    with open(REPO / "pyproject.toml", "rb") as f:
        conf = tomllib.load(f)["tool"]["ruff"]
    lint = conf["lint"]
    cmd = [sys.executable, "-m", "ruff", "check", "--no-cache", "--isolated"]
    cmd += ["--line-length", str(conf["line-length"]), "--select", ",".join(lint["select"])]
    cmd += ["--ignore", ",".join(lint["ignore"]), str(folder)]
    out = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    return "" if out.returncode == 0 else out.stdout + out.stderr


def mypy_problems(folder: Path, cache: Path) -> str:
    """'' when mypy --strict passes on every generated package."""
    cmd = [sys.executable, "-m", "mypy", "--strict", "--python-version", "3.11"]
    cmd += ["--cache-dir", str(cache), "--no-error-summary"]
    for package in packages(folder):
        cmd += ["-p", package]
    env = dict(os.environ, MYPYPATH=str(folder))
    out = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    return "" if out.returncode == 0 else out.stdout + out.stderr
