"""docs/TUTORIAL.md as a user runs it: each block marked `<!-- tutorial: run -->` runs in bash, in
a copy of this checkout, and prints the lines of the `<!-- tutorial: output -->` block after it."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from loopback import free_port
from miro_cli import REPO

TUTORIAL = REPO / "docs" / "TUTORIAL.md"
BLOCK = re.compile(
    r"<!-- tutorial: run -->\s*```sh\n(?P<run>.*?)```"
    r"(?:\s*<!-- tutorial: output -->\s*```text\n(?P<out>.*?)```)?",
    re.S,
)
SKIP = shutil.ignore_patterns(
    ".git", ".ci", "__pycache__", ".mypy_cache", ".pytest_cache", ".ruff_cache", "build",
    "node_modules", "*.egg-info",
)  # fmt: skip


def blocks() -> list[tuple[str, str]]:
    found = [(m["run"], m["out"] or "") for m in BLOCK.finditer(TUTORIAL.read_text())]
    assert len(found) >= 7, "the tutorial's blocks were not found"
    return found


@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the files of this checkout that git tracks, as a fresh clone (the tutorial
    writes into it): not the services a quick start here may have made."""
    root = tmp_path_factory.mktemp("tutorial") / "miro-gen"
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=False)
    if listed.returncode != 0:  # not a git checkout: copy what there is
        shutil.copytree(REPO, root, ignore=SKIP, symlinks=True)
        return root
    for name in listed.stdout.decode().split("\0"):
        source = REPO / name
        if not name or not (source.exists() or source.is_symlink()):
            continue  # deleted in the work tree
        target = root / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if source.is_symlink():
            target.symlink_to(os.readlink(source))
        else:
            shutil.copy2(source, target)
    subprocess.run(["git", "init", "-q"], cwd=root, check=True)  # so .gitignore applies
    return root


@pytest.mark.parametrize("index", range(len(blocks())))
def test_the_tutorial_runs_as_written(clone: Path, index: int) -> None:
    script, expected = blocks()[index]
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONPATH"] = os.pathsep.join([str(clone / "generated"), str(clone)])
    env["MIRO_NAMING"] = f"tcp://127.0.0.1:{free_port()}"  # the default port may be in use here
    prelude = "set -eu\ntrap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n"
    done = subprocess.run(
        ["bash", "-c", prelude + script],
        cwd=clone,
        env=env,
        capture_output=True,
        text=True,
        timeout=180,
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"block {index + 1} failed:\n{script}\n{output}"
    for line in expected.splitlines():
        if line.strip():
            assert line in output, f"block {index + 1}: {line!r} not in:\n{output}"


def test_what_the_tutorial_made_passes_the_repositorys_lint(clone: Path) -> None:
    """After the tutorial (which scaffolds services into the clone), the repository's own
    ruff settings still pass: its test command does not turn red."""
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed")
    if not (clone / "services" / "hello").is_dir():
        pytest.skip("the tutorial's blocks did not run first")
    for args in (["check", "--no-cache", "."], ["format", "--check", "--no-cache", "."]):
        done = subprocess.run([ruff, *args], cwd=clone, capture_output=True, text=True)
        assert done.returncode == 0, done.stdout + done.stderr
