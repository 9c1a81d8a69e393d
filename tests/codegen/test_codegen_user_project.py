"""Generated code is product code in a user's own project too: what miro-idl and miro-params
make of a user's IDL and parameter files (tests/codegen/project: several files, modules reopened
across files, two modules named `Util`, a module named like the standard library's `sched`, the
global scope, parameters in an IDL module's package and in a package of their own, an included
IDL file of the installed miro-gen's and its module Miro reopened) passes ruff check, with its
default rules and with typical settings, ruff format --check and mypy --strict, in a fresh
project that has none of this repository's settings; with the generated packages at the
project's root (`-o .`, where isort calls them first-party) or in a folder on sys.path
(`-o generated`, third-party). Every module imports there, beside the installed miro-gen."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import pytest
from miro_cli import REPO, run_miro_idl, run_miro_params

PROJECT = REPO / "tests" / "codegen" / "project"
# Typical settings of a project that sorts its imports (and the rules this repository selects).
SELECT = ["E", "F", "W", "I", "B", "UP", "SIM", "RUF"]
# The packages the miro-gen wheel carries (pyproject.toml: miro_gen, Miro*, _GlobalIDL*).
WHEEL = ["miro_gen", *(p.name for p in (REPO / "generated").iterdir() if p.name != "Test")]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder standing for the site-packages of an installed miro-gen, for mypy (which does
    not follow the editable install of the test environment): the wheel's packages, nothing
    else of the repository."""
    folder = tmp_path_factory.mktemp("site-packages")
    for name in WHEEL:
        source = REPO / name if name == "miro_gen" else REPO / "generated" / name
        (folder / name).symlink_to(source, target_is_directory=True)
    return folder


class Project(NamedTuple):
    root: Path
    out: str  # the output folder, relative to the root: on sys.path

    @property
    def packages(self) -> list[str]:
        folder = self.root / self.out
        return sorted(p.name for p in folder.iterdir() if (p / "__init__.py").is_file())


@pytest.fixture(scope="module", params=[".", "generated"], ids=["at-root", "in-generated"])
def project(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Project:
    """A user's project: its IDL and parameter files compiled into `-o .` or `-o generated`,
    and a pyproject.toml with typical ruff settings (and nothing for mypy)."""
    root = tmp_path_factory.mktemp("project")
    for folder in ("idl", "params"):
        shutil.copytree(PROJECT / folder, root / folder)
    (root / "pyproject.toml").write_text(
        '[project]\nname = "rover"\nversion = "1.0"\n\n'
        f"[tool.ruff.lint]\nselect = {SELECT!r}\n".replace("'", '"')
    )
    out = str(request.param)
    idl = sorted(f"idl/{p.name}" for p in (root / "idl").glob("*.idl"))
    result = run_miro_idl("-I", "idl", "-I", str(REPO / "idl"), "-o", out, *idl, cwd=root)
    assert result.returncode == 0, result.stderr
    assert "IDL module sched is the Python package sched, which hides" in result.stderr
    assert "not generated" not in result.stderr  # Miro.Time_idl: the installed miro-gen's
    params = sorted(f"params/{p.name}" for p in (root / "params").glob("*.xml"))
    result = run_miro_params("-o", out, *params, cwd=root)
    assert result.returncode == 0, result.stderr
    return Project(root, out)


def _run(cmd: list[str], cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        cmd,
        cwd=cwd,
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_project_holds_what_both_tools_generate(project: Project) -> None:
    assert project.packages == [
        "Geometry",
        "Miro",
        "Miro__POA",
        "Planner",
        "Rover",
        "Rover__POA",
        "_GlobalIDL",
        "sched",
        "sched__POA",
    ]
    out = project.root / project.out
    assert (out / "Rover" / "RoverParameters.py").is_file()  # in miro-idl's package
    assert (out / "Geometry" / "Util" / "geometry_idl.py").is_file()
    assert (out / "Rover" / "Util" / "rover_idl.py").is_file()


def test_ruff_default_rules_pass(project: Project) -> None:
    """No configuration at all (ruff's defaults, which include isort's I001, N999 and RUF100)."""
    cmd = [sys.executable, "-m", "ruff", "check", "--no-cache", "--isolated", "."]
    out = _run(cmd, project.root)
    assert out.returncode == 0, out.stdout + out.stderr


def test_ruff_typical_settings_pass(project: Project) -> None:
    """The project's pyproject.toml: isort and the usual families, ruff's line length (88)."""
    out = _run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], project.root)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "All checks passed" in out.stdout


def test_ruff_format_leaves_it_as_it_is(project: Project) -> None:
    """The templates' layout (100 columns) under ruff's formatter at its line length (88)."""
    cmd = [sys.executable, "-m", "ruff", "format", "--check", "--no-cache", "."]
    out = _run(cmd, project.root)
    assert out.returncode == 0, out.stdout + out.stderr


def test_mypy_strict_passes(project: Project, site: Path) -> None:
    cmd = [sys.executable, "-m", "mypy", "--strict", "--cache-dir", str(site.parent / "mypy")]
    out = _run([*cmd, project.out], project.root, MYPYPATH=str(site))
    assert out.returncode == 0, out.stdout + out.stderr


_IMPORT_ALL = """
import importlib, pkgutil, sys
for name in sys.argv[1:]:
    package = importlib.import_module(name)
    for info in pkgutil.walk_packages(package.__path__, name + "."):
        importlib.import_module(info.name)
import Planner.PlannerParameters, Rover, _GlobalIDL
assert Planner.PlannerParameters.PlannerParameters().drive.maxSpeed == 1.5
assert Rover.Drive.__module__ == "Rover.rover_idl"
assert _GlobalIDL.Heartbeat.__module__ == "_GlobalIDL.jobs_idl"
assert _GlobalIDL.Person.__module__ == "_GlobalIDL.Person_idl"  # the installed _GlobalIDL's
import Miro, Miro.SvcParameters
assert Miro.RoverStatus().stamp == Miro.TimeIDL()  # the project's Miro and the installed one
assert Miro.TimeIDL.__module__ == "Miro.Time_idl"
"""


def test_every_module_imports_beside_the_installed_packages(project: Project) -> None:
    """The project's `_GlobalIDL` and `Miro` and the ones the wheel carries are one package
    each."""
    cmd = [sys.executable, "-c", _IMPORT_ALL, *project.packages]
    out = _run(cmd, project.root, PYTHONPATH=project.out)
    assert out.returncode == 0, out.stdout + out.stderr
