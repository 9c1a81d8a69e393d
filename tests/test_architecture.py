"""The import layers of docs/ARCHITECTURE.md hold: `lint-imports` (import-linter) checks the
contracts in pyproject.toml's [tool.importlinter] over all of miro_gen: no module imports from a
floor above its own, the run time never imports the compilers, the code generator's stages
import only earlier stages, and no package has an import cycle among its modules or
subpackages. The few known exceptions are listed there by name, each with the pending work
that removes it; an exception that no longer matches an import fails the check too."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_import_layers() -> None:
    script = Path(sys.executable).with_name("lint-imports")
    if not script.exists():
        pytest.skip("import-linter is not installed (pip install -e '.[test]')")
    out = subprocess.run(
        [str(script), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stdout + out.stderr
