"""Running the project's command-line tools as a user does, for the tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_module(
    module: str, *args: str, cwd: Path | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """`python -m MODULE ARGS` in `cwd` (default: the repository), from this checkout."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(REPO), str(REPO / "generated"), env.get("PYTHONPATH", "")]
    )
    env.pop("MIRO_DEBUG", None)
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        cwd=cwd or REPO,
        env=env,
        capture_output=True,
        text=True,
        errors="replace",
        timeout=timeout,
    )


def run_miro_params(
    *args: str, cwd: Path | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """`miro-params ARGS` as a user runs it, from this checkout."""
    return run_module("miro_gen.cli.params", *args, cwd=cwd, timeout=timeout)


def run_miro_idl(
    *args: str, cwd: Path | None = None, timeout: float = 120, hash_seed: str | None = None
) -> subprocess.CompletedProcess[str]:
    """`miro-idl ARGS` in `cwd` (default: the repository), from this checkout, no debug output;
    with PYTHONHASHSEED set when `hash_seed` is given."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("MIRO_DEBUG", None)
    if hash_seed is not None:
        env["PYTHONHASHSEED"] = hash_seed
    return subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.idl", *args],
        cwd=cwd or REPO,
        env=env,
        capture_output=True,
        text=True,
        errors="replace",
        timeout=timeout,
    )
