"""makeParams' files with makeParams' meanings: the tree in tests/params/tree (a shared base, a
behaviour engine with abstract behaviours and arbiters, services deriving across folders, C++
default expressions, a namespace over two folders, a hand-written dummy class) is compiled as a
user compiles a Miro source tree, imported in a fresh interpreter, and its defaults are checked
value by value."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from miro_cli import REPO, run_miro_params, run_module
from params_helpers import write

TREE = REPO / "tests" / "params" / "tree"


def python(code: str, *path: Path) -> subprocess.CompletedProcess[str]:
    """Run `code` in a fresh interpreter with `path` first on sys.path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([*map(str, path), str(REPO), str(REPO / "generated")])
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        cwd=path[0] if path else REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The tree compiled as its own builds would: no -I (the includes are found in the folders
    above each file and their src/), into a folder that holds miro-idl's packages (package
    Miro is both), and the Video example into a second output folder."""
    out = tmp_path_factory.mktemp("tree") / "out"
    shutil.copytree(REPO / "generated", out)  # miro-idl's packages (Miro: ScanDescription_idl)
    files = sorted(str(p.relative_to(TREE)) for p in TREE.rglob("*.xml"))
    main = [f for f in files if not f.startswith("examples/")]
    result = run_miro_params("-o", str(out), *main, cwd=TREE)
    assert result.returncode == 0, result.stderr
    assert "error" not in result.stderr, result.stderr
    other = out.parent / "other"
    result = run_miro_params("-o", str(other), "examples/videoFilter/Filters.xml", cwd=TREE)
    assert result.returncode == 0, result.stderr
    return out, other


READ_DEFAULTS = """
    import json, math
    import Base.Parameters as B, Fusion.Parameters as F, Laser.Parameters as L
    import Miro.BAP.Parameters as BAP, Miro.Parameters as M, Miro.SvcParameters as S
    import Video.Filters as VF, Video.Parameters as V, wander.Parameters as W

    laser = L.Parameters()
    scan = laser.laserDescription
    base = B.Parameters()
    out = {
        "laser": [laser.MAX_BEAMS, laser.beams, math.degrees(laser.resolution),
                  laser.fieldOfView, laser.maxRange, laser.octal, laser.ratio, laser.third,
                  laser.retries, laser.mask, laser.echo, laser.pollInterval.microseconds,
                  laser.timeout.total_seconds(), laser.scheduling.policy,
                  laser.scheduling.priority, laser.weights, laser.spares, laser.mode,
                  laser.ttyParams.baudrate, laser.ttyParams.databits, laser.device],
        "scan": [scan.scanType, scan.eventName, len(scan.group), len(scan.group[0].sensor),
                 scan.group[0].description.maxRange, scan.group[0].description.focus,
                 math.degrees(scan.group[0].sensor[360].alpha), scan.group[0].sensor[0].masked,
                 scan.group[0].sensor[1].masked, scan.group[0].sensor[90].masked],
        "base": [base.motion.minTranslation, base.motion.wheelBase, base.motion.maxLTranslation,
                 math.degrees(base.motion.maxRotation), base.irHeight, base.scheduling.policy,
                 base.robotName],
        "fused": [F.FusedParameters().maxRange, F.FusedParameters().beams,
                  F.FusedParameters().delay.total_seconds(),
                  F.FusedParameters().base.motion.wheelBase],
        "svc": [S.LogNotifyParameters().tCRFileSize, S.LogNotifyParameters().maxFileSize,
                str(S.FocusParameters().rangeMax), S.TtyParameters().ttyParams.paritymode,
                S.TtyParameters().ttyParams.modem, S.TtyParameters().device,
                S.DifferentialMotionParameters().wheelBase],
        "robot": [M.RobotParameters.instance().name, M.RobotParameters.instance().teamSize,
                  M.CameraParameters().kappa, math.degrees(M.CameraParameters().alpha)],
        "bap": [BAP.TimedBehaviourParameters().pace.microseconds,
                [c.__name__ for c in BAP.MotionArbiterParameters.__mro__[:4]]],
        "wander": [W.WanderParameters().pace.microseconds,
                   W.WanderParameters().history.microseconds,
                   math.degrees(W.WanderParameters().rotation), W.AvoidLeftParameters().sensorName,
                   W.AvoidLeftParameters().lateralDistance, W.AvoidLeftParameters().turn,
                   W.BumperStopSlowParameters().backOff, W.BumperStopSlowParameters().halt,
                   W.BumperStopSlowParameters().stops(),
                   [c.__name__ for c in W.WanderArbiterParameters.__mro__[:5]]],
        "video": [V.VideoParameters().scheduling.policy, V.VideoParameters().filter.name,
                  V.DeviceDummyParameters().buffers, V.DeviceDummyParameters().whiteBalance,
                  V.DeviceDummyParameters().camera.latency.microseconds,
                  VF.FilterGrayParameters().threshold, VF.FilterGrayParameters().gain,
                  VF.FilterEdgesParameters().buffers],
        "instances": [hasattr(c, "instance") for c in (L.Parameters, S.TtyParameters,
                      S.LogNotifyParameters, V.FilterTreeParameters)],
        "exports": sorted(W.__all__),
    }
    print(json.dumps(out))
"""


def test_a_miro_tree_compiles_and_every_default_is_what_cxx_made(
    built: tuple[Path, Path],
) -> None:
    out, other = built
    result = python(READ_DEFAULTS, out, other, TREE / "python")
    assert result.returncode == 0, result.stderr
    got = json.loads(result.stdout)
    third = 1 / 3
    assert got["laser"] == [361, 360, 0.5, math.pi, 8000, 8, third, 0, 2, 2**32 - 1, True,
                            13333, 2.5, "SCHED_FIFO", 40, [0.25] * 3, [0, 0], "POLLED",
                            500000, 8, "/dev/ttyS0"]  # fmt: skip
    assert got["scan"][:6] == [2, "Laser", 1, 361, 8000, 0.00435]
    assert got["scan"][6] == pytest.approx(90.0)
    assert got["scan"][7:] == [True, False, True]  # i % 90 == 0
    # height[4] = {400, 120, 120}: the fourth is 0; scale 360/24 = 15, 360/8 = 45
    assert got["base"] == [-950, 425, 1000, 90.0, [415, 135, 165, 45], "SCHED_OTHER", "Miro"]
    assert got["fused"] == [4000, 360, 1.0, 425]
    assert got["svc"] == [2**20, 64 * 2**20, "inf", "none", False, "/dev/ttyS0", 390]
    assert got["robot"][:3] == ["Miro", 3, 0.0005]
    assert got["robot"][3] == pytest.approx(-15)
    assert got["bap"] == [
        50000,
        ["MotionArbiterParameters", "PriorityArbiterParameters", "ArbiterParameters", "Config"],
    ]
    assert got["wander"][:3] == [100000, 250000, pytest.approx(45.0)]
    assert got["wander"][3:9] == ["Infrared", 500, "LEFT", -50, True, True]
    assert got["wander"][9] == [
        "WanderArbiterParameters",
        "MotionArbiterParameters",
        "PriorityArbiterParameters",
        "ArbiterParameters",
        "Config",
    ]
    assert got["video"][:5] == ["SCHED_RR", "DeviceDummy", 1, "ON_OFF", 120000]
    assert got["video"][5:7] == [65, pytest.approx(2 * math.sqrt(2))]
    assert got["video"][7] == 3
    # instance="true" gives instance(); an abstract class (final="false") has none
    assert got["instances"] == [True, False, True, False]
    # dummy items have no class of their own (BumperStop, RandomTurn)
    assert got["exports"] == [
        "AvoidLeftParameters",
        "AvoidParameters",
        "BumperStopSlowParameters",
        "WanderArbiterParameters",
        "WanderParameters",
    ]


def test_generated_modules_pass_ruff_and_mypy_strict(built: tuple[Path, Path]) -> None:
    out, other = built
    config = str(REPO / "pyproject.toml")  # the rules generated/ is held to
    result = run_module("ruff", "check", "--no-cache", "--config", config, str(out), str(other))
    assert result.returncode == 0, result.stdout + result.stderr
    packages = ["Laser", "Base", "Fusion", "wander", "Video", "Miro.BAP", "Miro.SvcParameters"]
    search = os.pathsep.join([str(out), str(TREE / "python"), str(REPO)])
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--no-incremental", "--cache-dir=/dev/null",
         *(arg for p in packages for arg in ("-p", p))],
        env={**os.environ, "MYPYPATH": search},
        cwd=out, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr


def test_a_missing_hand_written_class_names_the_module_and_class_to_write(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    out, _ = built
    result = python("import wander.Parameters", out)
    assert result.returncode == 1
    assert (
        "ImportError: no module wander_bumper: BumperStop is a dummy item "
        "(botsvcs/examples/wander/Parameters.xml:27): its class is written by hand. Write class "
        "BumperStopParameters(miro_gen.params.Config) in the module wander_bumper "
        "(wander_bumper.py, on sys.path)"
    ) in result.stderr
    write(tmp_path / "wander_bumper.py", "class Other: pass\n")
    result = python("import wander.Parameters", tmp_path, out)
    assert "wander_bumper has no class BumperStopParameters deriving from Config" in result.stderr


def test_a_module_generated_from_an_included_file_is_named_when_missing(
    tmp_path: Path,
) -> None:
    out = tmp_path / "alone"
    result = run_miro_params("-o", str(out), "src/fusion/Parameters.xml", cwd=TREE)
    assert result.returncode == 0, result.stderr
    result = python("import Fusion.Parameters", out)
    assert (
        "ImportError: no module Base.Parameters: it is generated from src/base/Parameters.xml; "
        "compile it with `miro-params -o OUTDIR src/base/Parameters.xml`"
    ) in result.stderr


def test_the_tools_see_dummy_items_and_list_abstract_classes_only_when_asked(
    tmp_path: Path,
) -> None:
    doc = write(
        tmp_path / "robot.xml",
        """\
        <config>
          <section name="behaviour">
            <parameter name="RandomTurn"><parameter name="MaxTurn" value="45"/></parameter>
            <parameter name="BumperStop"><parameter name="Halt" value="no"/></parameter>
            <parameter name="Wander"><parameter name="Pace" value="0, 20000"/></parameter>
          </section>
        </config>
        """,
    )
    wander = str(TREE / "botsvcs/examples/wander/Parameters.xml")
    result = run_module("miro_gen.cli.params_tools", "validate", "-p", wander, str(doc))
    assert result.returncode == 0, result.stderr
    bad = write(tmp_path / "bad.xml", doc.read_text().replace("MaxTurn", "MaxTurns"))
    result = run_module("miro_gen.cli.params_tools", "show", "-p", wander, str(bad))
    # a stand-in made from the declaration, with its parent's parameters
    assert "'MaxTurns' (RandomTurnParameters has: Pace, MaxTurn)" in result.stderr
    odd = write(tmp_path / "odd.xml", doc.read_text().replace('"Wander"', '"Nothing"'))
    result = run_module("miro_gen.cli.params_tools", "show", "-p", wander, str(odd))
    assert "AvoidLeftParameters" in result.stderr and "AvoidParameters" not in result.stderr
    result = run_module("miro_gen.cli.params_tools", "show", "--all", "-p", wander, str(odd))
    assert "AvoidParameters" in result.stderr
    result = run_miro_params("--xsd", wander)
    assert result.returncode == 0 and '"MaxTurn"' in result.stdout


def test_expressions_outside_the_subset_are_errors_with_file_and_line(tmp_path: Path) -> None:
    src = write(
        tmp_path / "E.xml",
        """\
        <config>
          <config_item name="E">
            <config_parameter name="a" type="int" default="foo(1)" />
            <config_parameter name="b" type="int" default="1 / 0" />
            <config_parameter name="c" type="double" default="x.y" />
            <config_parameter name="d" type="long" default="(int)2.5 * 4" />
            <config_parameter name="e" type="unsigned short" default="1 &lt;&lt; 16" />
            <config_parameter name="f" type="ACE_Time_Value" default="1.5, 2" />
          </config_item>
        </config>
        """,
    )
    result = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert result.returncode == 1
    lines = result.stderr.splitlines()
    assert "E.xml:3: error: default='foo(1)': the function foo() is not supported" in lines
    assert "E.xml:4: error: default='1 / 0': integer division by zero" in lines
    assert "E.xml:5: error: default='x.y': x.y is not a constant" in lines
    assert not any(line.startswith("E.xml:6:") for line in lines)  # 8: C++ truncated first
    assert "E.xml:7: error: default='1 << 16': 65536 is outside the range" in result.stderr
    assert "E.xml:8: error: default='1.5, 2': an ACE_Time_Value takes whole" in result.stderr
    assert "Traceback" not in result.stderr


def test_bad_paths_are_one_line_errors(tmp_path: Path) -> None:
    src = write(
        tmp_path / "P.xml",
        '<config><config_global name="namespace" value="Blocked"/><config_item name="P"/></config>',
    )
    (tmp_path / "file").write_text("")
    result = run_miro_params("-o", str(tmp_path / "file"), str(src))
    assert result.returncode == 1
    message = f"error: the output folder '{tmp_path / 'file'}' is a file (-o OUTDIR)"
    assert result.stderr.strip() == message
    result = run_miro_params("-o", str(tmp_path / "out"), str(tmp_path))
    assert result.returncode == 1
    assert "is a folder, not a compile-time file" in result.stderr
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "Blocked").write_text("")  # where the package folder would go
    result = run_miro_params("-o", str(tmp_path / "out"), str(src))
    assert result.returncode == 1 and len(result.stderr.splitlines()) == 1
    assert "a file is in the way of a folder" in result.stderr
