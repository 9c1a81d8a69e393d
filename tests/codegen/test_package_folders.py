"""A package spread over several output folders is one package, whichever folder comes first on
sys.path: miro-idl's output and miro-params' (issue 14: `Miro.SvcParameters` was not found
when a folder with miro-idl's `Miro` came first), and IDL files compiled one by one into folders
of their own (module Geometry reopened in two files, Rover and its subpackage Util in two).
The modules of every folder import, and the package serves the names of all of them, also to
the event consumers' type-hash lookup."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from miro_cli import REPO, run_miro_idl, run_miro_params

PROJECT = REPO / "tests" / "codegen" / "project"

# folder -> what is compiled into it
FOLDERS = {
    "geometry": ["idl/geometry.idl"],
    "rover": ["idl/rover.idl"],
    "jobs": ["idl/jobs.idl"],
    "params": ["params/PlannerParameters.xml", "params/RoverParameters.xml"],
}

CHECK = """
import Geometry, Rover, sched
from miro_gen.runtime.cdr import type_for_hash

# before any module is imported: every folder's types, found by their hash
for package in (Geometry, Rover, Rover.Util):
    for type_hash, name in dict(package._TYPE_HASHES).items():
        assert type_for_hash(type_hash) is getattr(package, name), (package, name)
assert {"Point", "Segment"} <= set(Geometry._TYPE_HASHES.values())

assert Geometry.Point.__module__ == "Geometry.geometry_idl"
assert Geometry.Segment.__module__ == "Geometry.rover_idl"
assert Geometry.Util.Axis.Y_AXIS == 1 and Geometry.Util.EPSILON == 1e-9
assert Rover.Drive.__module__ == "Rover.rover_idl"
assert Rover.Util.Limits.__module__ == "Rover.Util.rover_idl"
assert Rover.Util.MAX_JOBS == 8
assert {"Drive", "Pose", "Stalled", "Util"} <= set(Rover.__all__) <= set(dir(Rover))
assert sched.Job().target == Rover.Pose()

import Planner.PlannerParameters, Rover.RoverParameters
assert Rover.RoverParameters.DriveParameters().maxSpeed == 1.5
assert Planner.PlannerParameters.PlannerParameters().drive.maxSpeed == 1.5

from Geometry import *  # noqa: F403
from Rover import *  # noqa: F403
assert Segment is Geometry.Segment and Stalled is Rover.Stalled  # noqa: F405
print(Rover.__file__)
"""


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Each of FOLDERS compiled by its own run of miro-idl or miro-params."""
    root = tmp_path_factory.mktemp("folders")
    for folder, files in FOLDERS.items():
        tool = run_miro_params if files[0].endswith(".xml") else run_miro_idl
        result = tool("-I", str(PROJECT / "idl"), "-o", str(root / folder), *files, cwd=PROJECT)
        assert result.returncode == 0, result.stderr
    return root


@pytest.mark.parametrize(
    "order", [list(FOLDERS), list(reversed(FOLDERS))], ids=["idl-first", "params-first"]
)
def test_each_order_on_sys_path_gives_one_package(folders: Path, order: list[str]) -> None:
    path = os.pathsep.join([*(str(folders / f) for f in order), str(REPO)])
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(CHECK)],
        cwd=folders,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    first = order[0] if order[0] != "geometry" else "rover"  # no Rover in the first folder
    assert out.stdout.strip() == str(folders / first / "Rover" / "__init__.py")
