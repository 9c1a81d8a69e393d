"""The CI definitions a team copies (GitHub Actions, pre-commit) run the checks .ci/run runs."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import yaml
from miro_cli import REPO

CHECKS = re.compile(r"^(miro-(?:idl|params) .*--check.*)$", re.M)


def test_the_workflow_checks_what_ci_checks() -> None:
    ci = CHECKS.findall((REPO / ".ci" / "run").read_text())
    workflow = yaml.safe_load((REPO / ".github" / "workflows" / "ci.yml").read_text())
    steps = "\n".join(s.get("run", "") for s in workflow["jobs"]["checks"]["steps"])
    assert ci and all(check in steps for check in ci)
    for command in ("ruff check .", "ruff format --check .", "mypy", "python -m pytest"):
        assert command in steps


def test_the_pre_commit_hooks_name_our_commands() -> None:
    hooks = yaml.safe_load((REPO / ".pre-commit-hooks.yaml").read_text())
    project = (REPO / "pyproject.toml").read_text()  # its [project.scripts]
    assert {h["id"] for h in hooks} == {"miro-idl-check", "miro-params-check"}
    for hook in hooks:
        assert hook["entry"].split()[0] + " = " in project
        assert "--check" in hook["entry"]


def test_this_projects_pre_commit_freshness_hook_passes() -> None:
    config = yaml.safe_load((REPO / ".pre-commit-config.yaml").read_text())
    hook = next(h for r in config["repos"] for h in r["hooks"] if h["id"] == "generated-fresh")
    path = f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}"
    done = subprocess.run(
        hook["entry"],
        shell=True,
        cwd=REPO,
        env=dict(os.environ, PATH=path),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
