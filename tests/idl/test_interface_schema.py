"""Interface schemas (miro_gen.codegen.interface_schema): the IDL text a server gives callers
that have no generated code. It must compile with miro-idl alone into the same interface: the
same operations, types with the same type hashes, exceptions with the same repository ids, and
(a fixed point) the same interface schema again."""

from __future__ import annotations

from pathlib import Path

import pytest
from repo_paths import REPO

from miro_gen.codegen.interface_schema import NoInterfaceSchema, interface_schema
from miro_gen.codegen.schema import data_schema
from miro_gen.idl import ast
from miro_gen.idl.frontend import compile_idl

TRICKY = """
#pragma prefix "acme.org"
module Lab {
  exception Busy { string why; long retry_ms; };
  interface Listener;
  typedef sequence<Listener> Listeners;
  struct Node;
  typedef sequence<Node> Nodes;
  struct Node { string name; Nodes children; };
  union Reading switch (short) {
    case 1: double value; case 2: string text; default: boolean none;
  };
  interface Base {
    readonly attribute string label;
    attribute long gain getraises (Busy) setraises (Busy);
  };
  interface Arm : Base {
    enum Mode { IDLE, MOVING };
    struct Pose { double x; double y; Mode state; };
    exception Limit { Pose reached; };
    Pose where();
    void move_to(in Pose target, in double speed, in double acceleration, out Pose reached)
      raises (Limit, Busy);
    oneway void stop();
    Listeners audience();
    void subscribe(in Listener who);
    Nodes tree();
    Reading read(inout long channel);
    Object any_object();
  };
  interface Listener { void moved(in Arm from, in Arm::Pose pose); };
};
"""


def resolved(path: Path, includes: tuple[str, ...] = ()) -> ast.Specification:
    return compile_idl(str(path), list(includes))


def interfaces(spec: ast.Specification) -> dict[str, ast.Interface]:
    return {d.scoped_name: d for d in spec.declarations if isinstance(d, ast.Interface)}


def data_hashes(spec: ast.Specification) -> dict[tuple[str, str], str]:
    return {
        (d.scoped_name, d.repo_id): data_schema(d)
        for d in spec.declarations
        if isinstance(d, ast.Struct | ast.Union_ | ast.Exception_)
    }


def round_trip(tmp_path: Path, spec: ast.Specification, name: str) -> tuple[str, ast.Specification]:
    text = interface_schema(interfaces(spec)[name], spec.declarations)
    again = tmp_path / f"{name.replace('::', '_')}.idl"
    again.write_text(text)
    return text, resolved(again)


def test_a_tricky_interface_compiles_back_into_itself(tmp_path: Path) -> None:
    source = tmp_path / "lab.idl"
    source.write_text(TRICKY)
    spec = resolved(source)
    text, back = round_trip(tmp_path, spec, "Lab::Arm")
    arm = interfaces(back)["Lab::Arm"]
    assert arm.repo_id == "IDL:acme.org/Lab/Arm:1.0"
    assert [op.name for op in arm.operations] == [
        "where",
        "move_to",
        "stop",
        "audience",
        "subscribe",
        "tree",
        "read",
        "any_object",
    ]
    assert [b.scoped_name for b in arm.bases] == ["Lab::Base"]
    assert "Lab::Listener" in interfaces(back)  # passed by reference: defined too
    original = data_hashes(spec)
    for key, schema in data_hashes(back).items():
        assert original[key] == schema, key  # same types, same hashes, same repository ids
    assert interface_schema(arm, back.declarations) == text  # a fixed point
    assert "    in double acceleration," in text  # a long operation, one parameter a line
    assert max(len(line) for line in text.splitlines()) <= 80


@pytest.mark.parametrize(
    "name", ["Miro::Example", "Miro::Gps", "Miro::RangeSensor", "MiroNaming::Registry"]
)
def test_the_projects_interfaces_compile_back_into_themselves(tmp_path: Path, name: str) -> None:
    idl = {
        "Miro::Example": "Example.idl",
        "Miro::Gps": "Gps.idl",
        "Miro::RangeSensor": "RangeSensor.idl",
        "MiroNaming::Registry": "MiroNaming.idl",
    }[name]
    spec = resolved(REPO / "idl" / idl, (str(REPO / "idl"),))
    text, back = round_trip(tmp_path, spec, name)
    assert interface_schema(interfaces(back)[name], back.declarations) == text
    original = data_hashes(spec)
    for key, schema in data_hashes(back).items():
        assert original[key] == schema, key


def test_the_generated_skeleton_carries_the_schema_and_the_stub_its_hash() -> None:
    import hashlib

    import Miro
    import Miro__POA

    schema = Miro__POA.Example._interface_schema
    assert "interface Example {" in schema
    assert Miro.Example._interface_hash == hashlib.sha256(schema.encode()).hexdigest()
    assert Miro__POA.Example._interface_hash == Miro.Example._interface_hash


def test_a_type_nested_in_a_struct_has_no_interface_schema(tmp_path: Path) -> None:
    source = tmp_path / "nested.idl"
    source.write_text(
        "module M { struct Outer { struct Inner { long x; } nested; };"
        " interface I { void f(in Outer::Inner i); }; };"
    )
    spec = resolved(source)
    with pytest.raises(NoInterfaceSchema, match="M::Outer::Inner is declared inside M::Outer"):
        interface_schema(interfaces(spec)["M::I"], spec.declarations)
