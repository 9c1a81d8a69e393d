"""`miro new` inside miro-gen's own repository writes code that passes the repository's own
lint: there miro_gen is first-party to ruff's isort, and its imports are a section of their
own (elsewhere it is one more package; tests/test_scaffold.py checks that case)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from miro_cli import REPO, run_module
from test_scaffold import PATTERNS

from miro_gen.scaffold.generate import separate_first_party


def test_new_services_pass_this_repositorys_ruff(tmp_path: Path) -> None:
    root = tmp_path / "miro-gen"
    root.mkdir()
    shutil.copy(REPO / "pyproject.toml", root)  # the repository's ruff settings
    shutil.copytree(REPO / "miro_gen", root / "miro_gen", symlinks=True)  # first-party here
    for folder in ("generated", "templates", "params"):  # (miro_gen links to the last two)
        shutil.copytree(REPO / folder, root / folder)
    for pattern in PATTERNS:
        done = run_module(
            "miro_gen.cli.main", "new", f"n_{pattern}", "--pattern", pattern, cwd=root
        )
        assert done.returncode == 0, done.stderr
    lint = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "services"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert lint.returncode == 0, lint.stdout + lint.stderr


def test_first_party_imports_go_in_a_block_of_their_own() -> None:
    text = (
        "import sys\n\nimport Miro\nfrom Arm.Parameters import ArmParameters\n"
        "from miro_gen import (\n    Server,\n)\nfrom miro_gen.params import read_parameters\n"
        "\nfrom .impl import Impl\n\nx = 1\n"
    )
    assert separate_first_party(text, frozenset({"miro_gen"})) == (
        "import sys\n\nimport Miro\nfrom Arm.Parameters import ArmParameters\n\n"
        "from miro_gen import (\n    Server,\n)\nfrom miro_gen.params import read_parameters\n"
        "\nfrom .impl import Impl\n\nx = 1\n"
    )
