"""`miro build` and miro_gen.cli.freshness: generated/ is regenerated when the project's IDL or
parameter files change, never silently left stale."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from miro_cli import REPO, run_module

from miro_gen.cli import freshness as proj


def make_project(tmp_path: Path) -> Path:
    root = tmp_path / "robot"
    (root / "idl").mkdir(parents=True)
    (root / "generated").mkdir()
    (root / "services" / "arm").mkdir(parents=True)
    shutil.copy(REPO / "idl" / "Example.idl", root / "idl")
    (root / "services" / "arm" / "ArmParameters.xml").write_text(
        '<config><config_global name="namespace" value="Arm"/><config_group name="Arm">'
        '<config_item name="Arm" instance="true">'
        '<config_parameter name="Speed" type="double" default="1.5"/>'
        "</config_item></config_group></config>"
    )
    return root


def test_build_makes_generated_fresh_and_keeps_it_so(tmp_path: Path) -> None:
    root = make_project(tmp_path)
    project = proj.find_project(root / "services" / "arm")
    assert project is not None and project.root == root
    state = proj.check(project)
    assert not state.fresh and state.stale
    done = run_module("miro_gen.cli.main", "build", cwd=root)
    assert done.returncode == 0, done.stderr
    assert "wrote generated/Miro/Example_idl.py" in done.stdout
    assert "wrote generated/Arm/ArmParameters.py" in done.stdout
    assert (root / ".miro" / "fresh.json").is_file()
    assert proj.check(project).fresh
    done = run_module("miro_gen.cli.main", "build", cwd=root)
    assert done.stdout.endswith("generated: up to date\n")
    idl = root / "idl" / "Example.idl"  # an edit: the interface gains an operation
    idl.write_text(
        idl.read_text().replace(
            "ExampleStructIDL getData();", "ExampleStructIDL getData();\n    void reset();"
        )
    )
    done = run_module("miro_gen.cli.main", "build", "--check", cwd=root)
    assert done.returncode == 1
    assert "generated/Miro/Example_idl.py is out of date" in done.stderr
    assert done.stderr.endswith(
        "miro build: run miro-idl -I idl idl/*.idl && miro-params -I idl "
        "services/*/*Parameters.xml\n"
    )
    assert proj.ensure_fresh(project) == [
        "wrote generated/Miro/Example_idl.py",
        "wrote generated/Miro__POA/Example_idl.py",
    ]
    assert "def reset(self)" in (root / "generated" / "Miro" / "Example_idl.py").read_text()


def test_inputs_that_do_not_compile_are_reported_not_run(tmp_path: Path) -> None:
    root = make_project(tmp_path)
    (root / "idl" / "Bad.idl").write_text("module M { struct S { long x } };\n")
    done = run_module("miro_gen.cli.main", "build", cwd=root)
    assert done.returncode == 1
    assert "idl/Bad.idl:1:" in done.stderr and "error:" in done.stderr


def test_a_tree_that_cannot_be_written_names_the_command(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = make_project(tmp_path)
    project = proj.find_project(root)
    assert project is not None
    real = proj.os.access
    generated = str(project.generated)
    monkeypatch.setattr(proj.os, "access", lambda p, mode: str(p) != generated and real(p, mode))
    with pytest.raises(proj.StaleError) as caught:
        proj.ensure_fresh(project)
    assert str(caught.value).endswith(
        "cannot be written here; run in "
        f"{root}: miro-idl -I idl idl/*.idl && miro-params -I idl services/*/*Parameters.xml"
    )


def test_outside_a_project_build_says_so(tmp_path: Path) -> None:
    done = run_module("miro_gen.cli.main", "build", cwd=tmp_path)
    assert done.returncode == 1
    assert "is not in a project" in done.stderr


def test_run_and_launch_regenerate_before_they_start(tmp_path: Path) -> None:
    root = make_project(tmp_path)
    show = root / "services" / "show"
    show.mkdir()
    (show / "__main__.py").write_text(
        "from Arm.ArmParameters import ArmParameters\nprint('speed', ArmParameters().speed)\n"
    )
    (root / "robot.toml").write_text('[services.show]\nrun = "services/show"\nrestart = "never"\n')
    done = run_module("miro_gen.cli.main", "run", "show", cwd=root)
    assert done.stdout == "speed 1.5\n", done.stderr
    assert "miro run: the IDL or parameter files changed: regenerated" in done.stderr
    xml = root / "services" / "arm" / "ArmParameters.xml"
    xml.write_text(xml.read_text().replace('default="1.5"', 'default="2.5"'))
    done = run_module("miro_gen.cli.main", "launch", "robot.toml", cwd=root)
    assert done.returncode == 0, done.stderr
    assert "show | speed 2.5" in " ".join(done.stdout.split())
    assert "miro launch: the IDL or parameter files changed: regenerated 1 files" in done.stderr
    done = run_module("miro_gen.cli.main", "run", "show", cwd=root)
    assert (done.stdout, done.stderr) == ("speed 2.5\n", "")


def test_a_changed_generator_makes_the_project_stale(tmp_path: Path) -> None:
    """miro-gen installed elsewhere (a copy of the package, its templates inside, as a wheel
    lays it out): after `miro build`, an edit of one of its templates (an upgrade) makes the
    project stale, for `miro build --check` as for the compilers' own --check."""
    site = tmp_path / "site"
    shutil.copytree(
        REPO / "miro_gen", site / "miro_gen", ignore=shutil.ignore_patterns("__pycache__")
    )
    assert not (site / "templates").exists()  # the copy's own templates are the ones it uses
    root = make_project(tmp_path)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(REPO / "generated")]))

    def miro(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *args],
            cwd=root, env=env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip

    done = miro("build")
    assert done.returncode == 0, done.stderr
    assert miro("build", "--check").returncode == 0
    template = site / "miro_gen" / "templates" / "params" / "module.py.j2"
    template.write_text(template.read_text() + "# one more line\n")
    done = miro("build", "--check")
    assert done.returncode == 1, done.stdout + done.stderr
    assert "generated/Arm/ArmParameters.py is out of date" in done.stderr
    done = miro("build")
    assert "wrote generated/Arm/ArmParameters.py" in done.stdout, done.stderr
    assert (root / "generated/Arm/ArmParameters.py").read_text().endswith("# one more line\n")


def test_building_leaves_the_process_as_it_was(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`miro run` and `miro launch` check freshness in their own process: compiling there
    changes neither its working folder, nor its garbage collector or recursion limit, and
    prints nothing (the compilers are a library, not their command lines). What it writes is
    what the commands write in the project's folder."""
    import gc

    root = make_project(tmp_path)
    project = proj.find_project(root)
    assert project is not None
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    limit = sys.getrecursionlimit()
    assert gc.isenabled()
    wrote = proj.ensure_fresh(project)
    assert "wrote generated/Miro/Example_idl.py" in wrote
    assert proj.check(project).fresh
    assert os.getcwd() == str(elsewhere) and gc.isenabled()
    assert sys.getrecursionlimit() == limit
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    for command in project.commands():
        module = {"miro-idl": "miro_gen.cli.idl", "miro-params": "miro_gen.cli.params"}
        done = run_module(module[command[0]], "--check", *command[1:], cwd=root)
        assert done.returncode == 0, done.stderr
