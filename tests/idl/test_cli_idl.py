"""`miro-idl` as a user runs it: flags, exit statuses, error format, JSON on stdout."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from miro_cli import run_miro_idl
from repo_paths import REPO

ROOT = REPO
ERROR_LINE = re.compile(
    r"^(?P<path>.+?):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning|note): .+$"
)


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_help_documents_every_flag() -> None:
    out = run_miro_idl("--help")
    assert out.returncode == 0
    flags = ("-I DIR", "-D NAME[=VALUE]", "-U NAME", "-o OUTDIR", "--check", "--ast-json")
    for flag in (*flags, "--case-sensitive", "--version"):
        assert flag in out.stdout, flag
    assert "FILE" in out.stdout


def test_version() -> None:
    out = run_miro_idl("--version")
    assert out.returncode == 0
    assert out.stdout.startswith("miro-idl ")


def test_ast_json_of_the_manual_example() -> None:
    out = run_miro_idl("--ast-json", "idl/Example.idl")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["files"] == ["idl/Example.idl"]
    names = [d["name"] for d in doc["declarations"]]
    assert names == [
        "Miro",
        "Miro::ExampleStructIDL",
        "Miro::ExampleListIDL",
        "Miro::ExampleGroupIDL",
        "Miro::ExampleEventIDL",
        "Miro::Example",
    ]
    example = doc["declarations"][-1]
    assert example["repo_id"] == "IDL:Miro/Example:1.0"
    assert [op["name"] for op in example["operations"]] == ["setData", "getData"]
    assert example["operations"][1]["returns"] == "Miro::ExampleStructIDL"


def test_errors_are_reported_in_compiler_format_without_traceback(tmp_path: Path) -> None:
    bad = write(tmp_path / "bad.idl", "module M {\n  struct S { long x };\n};\n")
    out = run_miro_idl("--ast-json", str(bad))
    assert out.returncode == 1
    assert out.stdout == ""
    assert "Traceback" not in out.stderr
    lines = out.stderr.strip().splitlines()
    assert lines, "no error message"
    m = ERROR_LINE.match(lines[0])
    assert m, lines[0]
    assert (m["path"], m["line"], m["col"], m["sev"]) == (str(bad), "2", "21", "error")
    assert "expected" in lines[0]


def test_every_file_is_checked_and_all_errors_reported(tmp_path: Path) -> None:
    a = write(tmp_path / "a.idl", "const long A = 1 / 0;\nconst short B = 70000;\n")
    b = write(tmp_path / "b.idl", "typedef Undeclared T;\n")
    out = run_miro_idl("--ast-json", str(a), str(b))
    assert out.returncode == 1
    errors = [ln for ln in out.stderr.splitlines() if ": error: " in ln]
    assert any(ln.startswith(f"{a}:1:") and "division by zero" in ln for ln in errors)
    assert any(ln.startswith(f"{a}:2:") and "too large for short" in ln for ln in errors)
    assert any(ln.startswith(f"{b}:1:") and "not declared" in ln for ln in errors)


def test_missing_file() -> None:
    out = run_miro_idl("--ast-json", "does/not/exist.idl")
    assert out.returncode == 1
    assert "cannot read 'does/not/exist.idl'" in out.stderr
    assert "Traceback" not in out.stderr


def test_include_dirs_and_defines(tmp_path: Path) -> None:
    write(
        tmp_path / "inc" / "Time.idl", "module Miro { struct TimeIDL { long sec; long usec; }; };\n"
    )
    main = write(
        tmp_path / "src" / "Main.idl",
        '#include "Time.idl"\n'
        "#if defined(WITH_STAMP) && SIZE > 2\n"
        "module Miro { struct Stamped { TimeIDL time; long data[SIZE]; }; };\n"
        "#endif\n",
    )
    out = run_miro_idl(
        "-I", str(tmp_path / "inc"), "-D", "WITH_STAMP", "-D", "SIZE=4", "--ast-json", str(main)
    )
    assert out.returncode == 0, out.stderr
    decls = {d["name"]: d for d in json.loads(out.stdout)["declarations"]}
    assert decls["Miro::TimeIDL"]["file"] == str(tmp_path / "inc" / "Time.idl")
    stamped = decls["Miro::Stamped"]
    assert stamped["members"][0]["type"] == "Miro::TimeIDL"
    assert stamped["members"][1]["dims"] == [4]
    # Without -I the include is an error naming the file and the searched folders.
    out = run_miro_idl("--ast-json", str(main))
    assert out.returncode == 1
    assert f"{main}:1:1: error: cannot find include file 'Time.idl'" in out.stderr
    assert str(tmp_path / "src") in out.stderr
    # -I attached to its value (-Idir) works as in other compilers.
    out = run_miro_idl(f"-I{tmp_path / 'inc'}", "--ast-json", str(main))
    assert out.returncode == 0, out.stderr


def test_bad_define_is_an_error(tmp_path: Path) -> None:
    f = write(tmp_path / "x.idl", "const long X = 1;\n")
    out = run_miro_idl("-D", "1BAD=2", "--ast-json", str(f))
    assert out.returncode == 1
    assert "invalid macro name" in out.stderr


def test_check_and_ast_json_are_exclusive(tmp_path: Path) -> None:
    f = write(tmp_path / "x.idl", "const long X = 1;\n")
    out = run_miro_idl("--check", "--ast-json", str(f))
    assert out.returncode == 2
    assert "not allowed with" in out.stderr


def test_warnings_do_not_fail(tmp_path: Path) -> None:
    f = write(tmp_path / "w.idl", "struct S { @custom_thing long x; };\n")
    out = run_miro_idl("--ast-json", str(f))
    assert out.returncode == 0
    assert f"{f}:1:12: warning: unknown annotation '@custom_thing'" in out.stderr
    member = json.loads(out.stdout)["declarations"][0]["members"][0]
    assert member["annotations"] == [{"name": "custom_thing", "params": {}}]


def test_miro_idl_subcommand_of_miro() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "idl", "--ast-json", "idl/Example.idl"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["files"] == ["idl/Example.idl"]


@pytest.mark.parametrize("script", ["miro", "miro-idl", "miro-params"])
def test_console_scripts_are_installed(script: str) -> None:
    path = Path(sys.executable).with_name(script)
    if not path.exists():
        pytest.skip(f"{script} is not installed next to {sys.executable} (pip install -e .)")
    out = subprocess.run([str(path), "--help"], capture_output=True, text=True, timeout=60)
    assert "Traceback" not in out.stderr


def _one_error_line(out: subprocess.CompletedProcess[str]) -> str:
    assert out.returncode == 1
    assert out.stdout == ""
    assert "Traceback" not in out.stderr and "internal error" not in out.stderr, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    return lines[0]


def test_output_folder_that_is_a_file(tmp_path: Path) -> None:
    write(tmp_path / "taken", "a file\n")
    idl = write(tmp_path / "A.idl", "module A { const long C = 1; };\n")
    line = _one_error_line(run_miro_idl("-o", str(tmp_path / "taken"), str(idl)))
    assert line == (
        f"error: -o {tmp_path / 'taken'}: the output folder is a file; "
        "give a folder (it is made if missing)"
    )
    line = _one_error_line(run_miro_idl("-o", str(tmp_path / "taken" / "sub"), str(idl)))
    assert f"the output folder is inside file '{tmp_path / 'taken'}'" in line
    assert (tmp_path / "taken").read_text() == "a file\n"


def test_input_that_is_a_folder(tmp_path: Path) -> None:
    line = _one_error_line(run_miro_idl("--ast-json", str(tmp_path)))
    assert line == f"error: cannot read '{tmp_path}': it is a folder, not an IDL file"


def test_modules_nested_too_deep_for_the_file_system(tmp_path: Path) -> None:
    """200 nested modules with long names parse (--ast-json), but their package path would
    exceed the file system's limit: generation refuses them with one line and writes nothing."""
    depth = 200
    text = "".join(f"module M{i}_{'x' * 24} {{ " for i in range(depth))
    text += "const long C = 1; " + "}; " * depth
    idl = write(tmp_path / "deep.idl", text + "\n")
    assert run_miro_idl("--ast-json", str(idl)).returncode == 0
    out_dir = tmp_path / "out"
    line = _one_error_line(run_miro_idl("-o", str(out_dir), str(idl)))
    assert line.startswith(
        "miro-idl: error: cannot generate IDL module M0_xxxxxxxxxxxxxxxxxxxxxxxx::"
    )
    assert line.endswith("(the file system allows 4095); nest fewer modules")
    assert not out_dir.exists()


def test_ast_json_of_omg_idl_imports_the_front_end_only() -> None:
    """`miro-idl --ast-json` starts in a few tens of milliseconds (issue 30: its whole run is
    compared with omniidl's): OMG IDL loads neither the ROS 2 readers and the Lark they use,
    nor the code generator and Jinja, nor `dataclasses`/`inspect` and `traceback`."""
    code = (
        "import contextlib, io, json, sys\n"
        "from miro_gen.cli import idl\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    code = idl.main(['-I', 'idl', '--ast-json', 'idl/Example.idl'])\n"
        "print(json.dumps([code, sorted(sys.modules)]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60
    )
    assert done.returncode == 0, done.stderr
    code, modules = json.loads(done.stdout)
    assert code == 0
    unwanted = ("lark", "jinja2", "dataclasses", "inspect", "traceback", "miro_gen.codegen")
    unwanted += ("miro_gen.idl.rosidl.unit", "miro_gen.idl.rosidl.msg_parser")
    assert [m for m in modules if m.startswith(unwanted)] == []
    assert "miro_gen.idl.parser" in modules  # it did compile
