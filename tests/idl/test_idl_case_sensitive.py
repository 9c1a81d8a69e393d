"""`--case-sensitive`: the DDS / ROS 2 reading of identifiers, as Cyclone's `idlc -f
case-sensitive` reads them, beside CORBA's (omniidl's) default.

CORBA: identifiers that differ only in case collide, a use reserves its first identifier in the
scope, and an identifier equal to a keyword ignoring case is an error. Case-sensitive: names are
distinct unless spelled alike, a use reserves nothing, only a keyword's exact spelling is one,
and where only a name can stand a keyword is that name (as ROS 2's rosidl parser reads
`sequence<int32> sequence;`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from miro_cli import run_miro_idl
from repo_paths import TESTS

from miro_gen.diagnostics import CompileError, Diagnostics
from miro_gen.idl import compile_idl
from miro_gen.idl.ast_json import specifications_json

ROS2 = TESTS / "codegen" / "dds" / "ros2"


def compile_text(
    tmp_path: Path, text: str, case_sensitive: bool
) -> tuple[dict[str, dict[str, Any]] | None, list[str]]:
    path = tmp_path / "t.idl"
    path.write_text(text, encoding="utf-8")
    diag = Diagnostics()
    try:
        spec = compile_idl(str(path), [], None, diag, case_sensitive=case_sensitive)
    except CompileError:
        return None, [d.message for d in diag.items if d.severity == "error"]
    decls = {d["name"]: d for d in specifications_json([str(path)], [spec])["declarations"]}
    return decls, [d.message for d in diag.items if d.severity == "warning"]


DDS_STYLE = """
module dds {
  enum Color { RED, GREEN };
  struct Header { long stamp; };
  struct Shape { Color color; Header header; long x; long X; };
  struct String { string data; };
  struct FOO_ { octet foo_[4]; };
  struct Seq { sequence<long> sequence; long in; };
};
"""


def test_dds_style_is_corba_errors_by_default(tmp_path: Path) -> None:
    decls, errors = compile_text(tmp_path, DDS_STYLE, case_sensitive=False)
    assert decls is None
    assert any("earlier use of 'Color'" in e for e in errors)
    assert any("member 'X' clashes with member 'x'" in e for e in errors)
    assert "identifier 'String' clashes with keyword 'string'" in errors
    assert any("'sequence' is a keyword" in e for e in errors)


def test_dds_style_compiles_case_sensitive(tmp_path: Path) -> None:
    decls, warnings = compile_text(tmp_path, DDS_STYLE, case_sensitive=True)
    assert decls is not None and not warnings
    shape = decls["dds::Shape"]
    assert [(m["name"], m["type"]) for m in shape["members"]] == [
        ("color", "dds::Color"),
        ("header", "dds::Header"),
        ("x", "long"),
        ("X", "long"),
    ]
    assert decls["dds::String"]["members"][0]["name"] == "data"
    assert [m["name"] for m in decls["dds::Seq"]["members"]] == ["sequence", "in"]


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("struct S { long a; long a; };", "member 'a' is already declared in this scope"),
        ("struct S { long S; };", "member 'S' clashes with the name of its enclosing scope"),
        ("struct Header { long x; }; typedef header H;", "'header' is not declared"),
        ("module M { struct T { long x; }; }; typedef m::T U;", "'m::T' is not declared"),
    ],
)
def test_case_sensitive_errors(tmp_path: Path, text: str, error: str) -> None:
    decls, errors = compile_text(tmp_path, text, case_sensitive=True)
    assert decls is None
    assert any(error in e for e in errors), errors


def test_names_differing_in_case_are_distinct(tmp_path: Path) -> None:
    text = "struct Foo { long foo; }; typedef Foo foo; const long FOO = 1;\n"
    decls, _ = compile_text(tmp_path, text, case_sensitive=True)
    assert decls is not None
    assert decls["foo"]["type"] == "Foo"
    assert decls["FOO"]["value"] == 1


def test_rosidl_tree_with_includes() -> None:
    """A ROS 2 file as rosidl writes it, its includes found through -I."""
    path = ROS2 / "sensor_msgs" / "msg" / "BatteryState.idl"
    spec = compile_idl(str(path), [str(ROS2)], case_sensitive=True)
    decls = {d["name"]: d for d in specifications_json([str(path)], [spec])["declarations"]}
    state = decls["sensor_msgs::msg::BatteryState"]
    assert state["doc"] is None
    verbatim = state["annotations"][0]
    assert verbatim["name"] == "verbatim"
    assert verbatim["params"]["language"] == "comment"
    assert verbatim["params"]["text"].startswith("Constants are chosen to match the enums")
    by_name = {m["name"]: m for m in state["members"]}
    assert by_name["header"]["type"] == "std_msgs::msg::Header"
    assert by_name["voltage"]["annotations"][-1] == {"name": "unit", "params": {"value": "V"}}
    assert by_name["power_supply_status"]["annotations"] == [
        {"name": "default", "params": {"value": 0}}
    ]
    assert by_name["serial_number"]["type"] == "string<16>"
    assert by_name["raw"]["type"] == "sequence<uint8>"
    constants = decls["sensor_msgs::msg::BatteryState_Constants::DEFAULT_LOCATION"]
    assert constants["value"] == 'slot "A"'
    assert decls["std_msgs::msg::Header"]["members"][0]["type"] == "builtin_interfaces::msg::Time"


def test_cli_flag(tmp_path: Path) -> None:
    assert "--case-sensitive" in run_miro_idl("--help").stdout
    idl = tmp_path / "s.idl"
    idl.write_text(DDS_STYLE, encoding="utf-8")
    assert run_miro_idl("--ast-json", str(idl)).returncode == 1
    out = run_miro_idl("--case-sensitive", "--ast-json", str(idl))
    assert out.returncode == 0, out.stderr
    names = [d["name"] for d in json.loads(out.stdout)["declarations"]]
    assert "dds::Shape" in names
