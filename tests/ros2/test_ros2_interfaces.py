"""ROS 2 interfaces (`.msg`, `.srv`, `.action` and rosidl's `.idl`) against ROS 2's own tools,
on every interface file the Kilted wheels from PyPI ship (common_interfaces, rcl_interfaces,
test_msgs and what they use), installed in a virtual environment of their own
(tests/ros2_env.py) and read from its `share/` folder.

- Each `.msg`/`.srv`/`.action` compiles to the AST its `.idl` (rosidl_adapter's) compiles to.
- Each `.idl` compiles, and its structs agree with rosidl_parser's parse
  (tests/rosidl_differential.py).
- Every RIHS01 hash in the wheels' `.json` files equals miro-idl's, and the generated classes carry
  them (`_ros2_type`, `_ros2_type_hash`).
- A new message of every type holds what rosidl_generator_py's class gives it (zeros and the
  interface file's default values).
- The generated CDR equals rosbags' (an independent ROS 2 codec, reading the `.msg` files) for
  random values of every message type, those rosidl derives for services and actions included,
  and each side decodes the other's bytes.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import codegen_helpers as H
import pytest
import ros2_env
import rosidl_differential as R
from hypothesis import given, settings
from hypothesis import strategies as st
from miro_cli import run_miro_idl

from miro_gen.diagnostics import CompileError, Diagnostics
from miro_gen.idl import ast, compile_idl

ROS2, REASON = ros2_env.available()
pytestmark = pytest.mark.skipif(ROS2 is None, reason=REASON or "")
SHARE = ROS2.share if ROS2 is not None else Path("/nonexistent")
INTERFACES = R.interface_files(SHARE)
IDLS = R.idl_files(SHARE)


def _id(p: Path) -> str:
    return str(p.relative_to(SHARE))


@pytest.mark.parametrize("path", INTERFACES, ids=_id)
def test_interface_file_gives_the_ast_of_its_idl(path: Path) -> None:
    spec = R.compile_file(path, SHARE)
    assert R.ast_json_of_main(spec) == R.ast_json_of_main(
        R.compile_file(path.with_suffix(".idl"), SHARE)
    )
    assert R.miro_hashes(spec).items() >= R.json_hashes(path).items()


@pytest.fixture(scope="module")
def rosidl_parsed(ros2: ros2_env.Ros2Env) -> dict[Path, Any]:
    """rosidl_parser's structs of every `.idl` file, by file (one run in the ROS 2 environment)."""
    return R.rosidl_structs(ros2, IDLS)


@pytest.mark.parametrize("path", IDLS, ids=_id)
def test_idl_agrees_with_rosidl_parser_and_its_hashes(
    path: Path, rosidl_parsed: dict[Path, Any]
) -> None:
    spec = R.compile_file(path, SHARE)
    assert R.agrees(spec, rosidl_parsed[path])
    want = R.json_hashes(path)
    assert {k: R.miro_hashes(spec).get(k) for k in want} == want


def test_the_wheels_ship_what_the_issue_names() -> None:
    packages = {p.parent.parent.name for p in IDLS}
    assert {"std_msgs", "geometry_msgs", "sensor_msgs", "rcl_interfaces", "test_msgs"} <= packages
    assert len(INTERFACES) >= 180 and len(IDLS) >= 190


def test_service_and_action_derived_types() -> None:
    spec = R.compile_file(SHARE / "test_msgs" / "action" / "Fibonacci.action", SHARE)
    structs = {d.scoped_name: d for d in spec.declarations if isinstance(d, ast.Struct)}
    p = "test_msgs::action::Fibonacci"
    for suffix in (
        "_Goal", "_Result", "_Feedback", "_SendGoal_Request", "_SendGoal_Response",
        "_SendGoal_Event", "_SendGoal", "_GetResult_Request", "_GetResult_Response",
        "_GetResult_Event", "_GetResult", "_FeedbackMessage", "",
    ):  # fmt: skip
        assert p + suffix in structs and p + suffix in spec.ros2_hashes
    event = structs[p + "_SendGoal_Event"]
    assert [m.name for m in event.members] == ["info", "request", "response"]
    assert [m.name for m in structs[p].members] == [
        "goal", "result", "feedback", "send_goal_service", "get_result_service",
        "feedback_message",
    ]  # fmt: skip


# ---- what users write ----------------------------------------------------------------------


def compile_text(tmp_path: Path, name: str, text: str) -> tuple[Any, list[str]]:
    path = tmp_path / "my_pkg" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    diag = Diagnostics()
    try:
        return compile_idl(str(path), [str(SHARE)], None, diag), []
    except CompileError:
        return None, [str(d) for d in diag.items]


def test_a_user_package_with_comments_units_defaults_and_constants(tmp_path: Path) -> None:
    spec, errors = compile_text(
        tmp_path,
        "msg/Reading.msg",
        "# A reading of the range sensor.\n"
        "\n"
        "# The first line of the comment\n"
        "std_msgs/Header header\n"
        "float32 range 1.5  # [m] the distance\n"
        "    # (more about the range)\n"
        "uint8 MODE_FAST=1\n"
        "string<=8 name 'front'\n"
        "int32[<=4] history [1, -2]\n"
        "Other[2] others\n",
    )
    assert spec is None and any("cannot find my_pkg/msg/Other" in e for e in errors)
    (tmp_path / "my_pkg" / "msg" / "Other.msg").write_text("bool flag\n", encoding="utf-8")
    spec, errors = compile_text(
        tmp_path, "msg/Reading.msg", (tmp_path / "my_pkg/msg/Reading.msg").read_text()
    )
    assert not errors
    decls = {d.scoped_name: d for d in spec.declarations}
    reading = decls["my_pkg::msg::Reading"]
    rng = reading.members[1]
    anns = {a.short_name: a.params for a in rng.annotations}
    assert anns["default"] == {"value": 1.5} and anns["unit"] == {"value": "m"}
    # as rosidl_adapter's parse_message_string reads it
    assert anns["verbatim"]["text"] == "the distance\n(more about the range)"
    assert {a.short_name: a.params for a in reading.annotations}["verbatim"]["text"] == (
        "A reading of the range sensor."
    )
    header = {a.short_name: a.params for a in reading.members[0].annotations}
    assert header["verbatim"]["text"] == "The first line of the comment"
    assert decls["my_pkg::msg::Reading_Constants::MODE_FAST"].value == 1
    assert "my_pkg::msg::my_pkg__msg__Other__2" in decls
    assert spec.ros2_hashes["my_pkg::msg::Reading"].startswith("RIHS01_")


@pytest.mark.parametrize(
    ("name", "text", "error"),
    [
        (
            "msg/Bad.msg",
            "int32 x\nfloat64 Y\n",
            "Bad.msg:2:9: error: 'Y' is not a valid field name",
        ),
        (
            "msg/Bad.msg",
            "int32 X=1.5\n",
            "Bad.msg:1:1: error: constant 'X': '1.5' is not an integer",
        ),
        ("msg/Bad.msg", "uint8 x 300\n", "uint8 value 300 is outside 0 .. 255"),
        ("msg/Bad.msg", "int32 x\n---\nint32 y\n", "1 '---' lines: a .msg file has no '---' line"),
        ("srv/Bad.srv", "int32 x\n", "a .srv file has one '---' line"),
        ("msg/Bad.msg", "time stamp\n", "'time' is ROS 1's; ROS 2 writes builtin_interfaces/Time"),
        ("msg/Bad.msg", "int32[x] a\n", "the size of array type 'int32[x]' must be an integer"),
        ("msg/Bad.msg", "int32 x\nint32 x\n", "Bad.msg:2:1: error: field 'x' is defined twice"),
        ("msg/Bad.msg", "  int32 x\n", "Bad.msg:1:3: error: cannot read 'int32 x'"),
    ],
)
def test_errors_name_the_line(tmp_path: Path, name: str, text: str, error: str) -> None:
    spec, errors = compile_text(tmp_path, name, text)
    assert spec is None
    assert any(error in e for e in errors), errors


def test_cli_generates_ros2_types_with_their_hashes(tmp_path: Path) -> None:
    out = tmp_path / "out"
    files = [SHARE / "std_msgs/msg/Header.msg", SHARE / "builtin_interfaces/msg/Time.msg"]
    r = run_miro_idl("-I", str(SHARE), "-o", str(out), *map(str, files))
    assert r.returncode == 0, r.stderr
    idl_out = tmp_path / "idl"
    r = run_miro_idl("--ros2", "-I", str(SHARE), "-o", str(idl_out),
                     *(str(f.with_suffix(".idl")) for f in files))  # fmt: skip
    assert r.returncode == 0, r.stderr
    from_idl = {k: v.replace(b".idl", b".msg") for k, v in H.tree(idl_out).items()}
    assert from_idl == H.tree(out)  # the same code, but for the name of the source
    r = run_miro_idl("-I", str(SHARE), "--ast-json", str(files[0]))
    assert r.returncode == 0, r.stderr
    by_name = {d["name"]: d for d in json.loads(r.stdout)["declarations"]}
    want = R.json_hashes(files[0])
    assert by_name["std_msgs::msg::Header"]["ros2_type_hash"] == want["std_msgs/msg/Header"]
    time_hash = by_name["builtin_interfaces::msg::Time"]["ros2_type_hash"]
    assert time_hash == R.json_hashes(files[1])["builtin_interfaces/msg/Time"]
    packages = {"std_msgs", "builtin_interfaces"}
    H.forget_packages(packages)  # other tests generate packages of these names elsewhere
    sys.path.insert(0, str(out))
    try:
        header = importlib.import_module("std_msgs.msg").Header
        assert (header._ros2_type, header._ros2_type_hash) == (
            "std_msgs/msg/Header",
            want["std_msgs/msg/Header"],
        )
    finally:
        sys.path.remove(str(out))
        H.forget_packages(packages)


# ---- CDR against rosbags -------------------------------------------------------------------

SECTIONS = {
    "msg": [""],
    "srv": ["_Request", "_Response"],
    "action": ["_Goal", "_Result", "_Feedback"],
}


def rosbags_types() -> dict[str, Any]:
    """rosbags' reading of every `.msg` (and of the sections of `.srv` and `.action` files),
    and of the `.idl` files without a `.msg` that its IDL reader takes."""
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    types: dict[str, Any] = {}
    for f in INTERFACES:
        kind = f.parent.name
        sections: list[list[str]] = [[]]
        for line in f.read_text(encoding="utf-8").splitlines():
            sections.append([]) if line == "---" else sections[-1].append(line)
        package = f.parent.parent.name
        for lines, suffix in zip(sections, SECTIONS[kind], strict=True):
            # rosbags reads a section as a message `pkg/msg/...`: so it resolves the section's
            # package-relative names to `pkg/msg/`, as rosidl does (given `pkg/srv/X` it would
            # name the type `pkg/srv/msg/X`, and `pkg/action/X` resolves them to `pkg/action/`).
            # The type is registered under its ROS 2 name.
            as_msg = f"{package}/msg/{f.stem}{suffix}"
            parsed = get_types_from_msg("\n".join(lines), as_msg)
            types[f"{package}/{kind}/{f.stem}{suffix}"] = parsed.pop(as_msg)
            types.update(parsed)
    for f in IDLS:
        if not any(f.with_suffix(s).exists() for s in (".msg", ".srv", ".action")):
            try:
                types.update(get_types_from_idl(f.read_text(encoding="utf-8")))
            except Exception:  # rosbags' IDL reader refuses `@key` members (test_msgs)
                continue
    return types


# The messages rosidl derives for each service and action: rosbags reads no file that holds
# them, so their rosbags definitions are made from the structs miro-idl compiled (which
# test_idl_agrees_with_rosidl_parser_and_its_hashes compares with rosidl_parser's).
DERIVED = {
    "srv": ["_Event"],
    "action": [
        "_SendGoal_Request", "_SendGoal_Response", "_SendGoal_Event", "_GetResult_Request",
        "_GetResult_Response", "_GetResult_Event", "_FeedbackMessage",
    ],
}  # fmt: skip
DERIVED_TYPES = [
    f"{f.parent.parent.name}/{f.parent.name}/{f.stem}{suffix}"
    for f in INTERFACES
    for suffix in DERIVED.get(f.parent.name, [])
]
ROSBAGS_TYPES = sorted(rosbags_types()) if ROS2 is not None else []
# rosbags has no wstring codec (its typesys says so): that message is checked on its own.
NO_ROSBAGS_CODEC = {"test_msgs/msg/WStrings"}
CDR_TYPES = [t for t in ROSBAGS_TYPES if t not in NO_ROSBAGS_CODEC] + DERIVED_TYPES

# rosbags' names of the IDL types of ROS 2's primitives
ROS_PRIMS = {
    "boolean": "bool", "octet": "byte", "uint8": "uint8", "int8": "int8", "short": "int16",
    "unsigned short": "uint16", "long": "int32", "unsigned long": "uint32", "long long": "int64",
    "unsigned long long": "uint64", "float": "float32", "double": "float64",
}  # fmt: skip


def rosbags_definition(decl: ast.Struct) -> Any:
    """A struct as rosbags' type store takes a message definition: (constants, fields)."""
    from rosbags.interfaces import Nodetype

    def node(ty: H.Ty) -> Any:
        if ty.kind == "prim":
            return (Nodetype.BASE, (ROS_PRIMS[ty.prim], 0))
        if ty.kind == "string":
            return (Nodetype.BASE, ("string", ty.bound or 0))
        if ty.kind == "seq" and ty.elem is not None:
            return (Nodetype.SEQUENCE, (node(ty.elem), ty.bound or 0))
        if ty.kind == "array" and ty.elem is not None and len(ty.dims) == 1:
            return (Nodetype.ARRAY, (node(ty.elem), ty.dims[0]))
        assert ty.kind == "struct", ty
        return (Nodetype.NAME, "/".join(ty.decl.scope_path))

    fields = [(m.name, node(t)) for m, t in zip(H.members(decl), H.member_types(decl), strict=True)]
    return ([], fields)


class Structs(dict[str, Any]):
    """The generated structs by ROS 2 type name (a short repr for hypothesis' reports), and the
    folder their code was generated into."""

    out = Path()

    def __repr__(self) -> str:
        return f"<{len(self)} ROS 2 structs>"


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Structs]:
    """Every interface generated into one folder; the resolved structs by ROS 2 type name."""
    out = tmp_path_factory.mktemp("ros2") / "out"
    idl_only = [
        f for f in IDLS if not any(f.with_suffix(s).exists() for s in (".msg", ".srv", ".action"))
    ]
    files = [*INTERFACES, *idl_only]
    r = run_miro_idl("--ros2", "-I", str(SHARE), "-o", str(out), *map(str, files))
    assert r.returncode == 0, r.stderr
    specs = [R.compile_file(f, SHARE) for f in files]
    structs = Structs(
        ("/".join(d.scope_path), d)
        for s in specs
        for d in s.declarations
        if isinstance(d, ast.Struct) and d.pos.path == s.main_file
    )
    structs.out = out
    sys.path.insert(0, str(out))
    try:
        with H.registered(specs):
            yield structs
    finally:
        sys.path.remove(str(out))


@pytest.fixture(scope="module")
def typestore(generated: Structs) -> Any:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.EMPTY)
    store.register(rosbags_types())
    store.register({name: rosbags_definition(generated[name]) for name in DERIVED_TYPES})
    return store


def test_every_generated_type_carries_its_hash(generated: dict[str, Any]) -> None:
    hashes: dict[str, str] = {}
    for f in IDLS:
        hashes |= R.json_hashes(f)
    checked = 0
    for name, decl in generated.items():
        cls = H.pyclass(decl)
        assert cls._ros2_type == name
        if name in hashes:
            assert cls._ros2_type_hash == hashes[name]
            checked += 1
    assert checked == len(generated) >= 280


def test_new_messages_hold_what_rosidl_generator_py_gives(
    generated: Structs, ros2: ros2_env.Ros2Env
) -> None:
    """A new message of every type holds the values rosidl_generator_py's class (the Python the
    wheels ship) gives one: zeros, and the `@default` values of the interface file."""
    theirs = ros2.run_json("py_defaults.py", *sorted(generated))
    checked = 0
    for name, values in theirs.items():
        if values is None:  # the service and action types themselves: no message class there
            continue
        assert as_rosidl_py(H.pyclass(generated[name])()) == values, name
        checked += 1
    assert checked >= 250


def as_rosidl_py(v: Any) -> Any:
    """A generated value in py_defaults.py's JSON shapes. rosidl_generator_py's classes hide the
    member rosidl gives an empty message (`structure_needs_at_least_one_member`, on the wire):
    so does this."""
    if dataclasses.is_dataclass(v):
        names = [f.name for f in dataclasses.fields(v)]
        if names == ["structure_needs_at_least_one_member"]:
            return []
        return [as_rosidl_py(getattr(v, n)) for n in names]
    if isinstance(v, list):
        return [as_rosidl_py(x) for x in v]
    return json.loads(json.dumps(plain(v)))


def test_generated_code_passes_ruff_and_mypy_strict(generated: Structs, tmp_path: Path) -> None:
    import generated_checks as G

    assert not G.ruff_problems(generated.out)
    assert not G.mypy_problems(generated.out, tmp_path / "mypy-cache")


# numpy's names of the IDL types of numbers. rosbags holds ROS 2's `byte` (IDL `octet`, 0..255
# on the wire and in rosidl_generator_py) as ROS 1's signed int8: the same bytes.
DTYPES = {
    "boolean": "bool", "octet": "int8", "uint8": "uint8", "int8": "int8", "short": "int16",
    "unsigned short": "uint16", "long": "int32", "unsigned long": "uint32", "long long": "int64",
    "unsigned long long": "uint64", "float": "float32", "double": "float64",
}  # fmt: skip


def to_rosbags(store: Any, ty: H.Ty, v: Any) -> Any:
    """A generated value as rosbags' message classes hold it."""
    import numpy

    if ty.kind in ("seq", "array") and ty.elem is not None:
        if ty.elem.kind == "prim":
            data = [to_rosbags(store, ty.elem, x) for x in v]
            return numpy.array(data, dtype=DTYPES[ty.elem.prim])
        return [to_rosbags(store, ty.elem, x) for x in v]
    if ty.kind == "struct":
        decl = ty.decl
        cls = store.types["/".join(decl.scope_path)]
        parts = [
            to_rosbags(store, t, getattr(v, f))
            for f, t in zip(H.fields_of(decl), H.member_types(decl), strict=True)
        ]
        return cls(*parts)
    if ty.kind == "prim" and ty.prim == "octet":
        return v - 256 if v > 127 else v
    return v


def from_rosbags(ty: H.Ty, v: Any) -> Any:
    """A value rosbags decoded, in `plain`'s shapes of the generated value."""
    if ty.kind in ("seq", "array") and ty.elem is not None:
        return (
            [from_rosbags(ty.elem, x) for x in plain(v)]
            if ty.elem.kind == "prim"
            else [from_rosbags(ty.elem, x) for x in v]
        )
    if ty.kind == "struct":
        values = plain_fields(v)
        types = H.member_types(ty.decl)
        return tuple(from_rosbags(t, x) for t, x in zip(types, values, strict=True))
    if ty.kind == "prim" and ty.prim == "octet":
        return v & 0xFF
    return plain(v)


def plain_fields(v: Any) -> list[Any]:
    """The values of a dataclass's fields. rosbags' constants and __msgtype__ are ClassVars,
    but annotated as strings in the classes it makes at run time, where dataclasses takes them
    for fields."""
    return [
        getattr(v, f.name)
        for f in dataclasses.fields(v)
        if not str(f.type).startswith(("ClassVar", "typing.ClassVar"))
    ]


def plain(v: Any) -> Any:
    """Values as nested lists and tuples of Python numbers and strings."""
    if dataclasses.is_dataclass(v):
        return tuple(plain(x) for x in plain_fields(v))
    if isinstance(v, bytes | bytearray):
        return list(v)
    if hasattr(v, "tolist"):
        return plain(v.tolist())
    if isinstance(v, list | tuple):
        return [plain(x) for x in v]
    return v


@pytest.mark.parametrize("name", CDR_TYPES)
@settings(H.SETTINGS, max_examples=8)
@given(data=st.data())
def test_cdr_equals_rosbags_both_ways(
    generated: dict[str, Any], typestore: Any, name: str, data: st.DataObject
) -> None:
    decl = generated[name]
    ty = H.resolve(decl)
    value = data.draw(H.values(ty, oracle=True))
    ours = value.serialize()
    theirs = typestore.serialize_cdr(to_rosbags(typestore, ty, value), name)
    assert ours == bytes(theirs)
    decoded = plain(H.pyclass(decl).deserialize(bytes(theirs)))
    assert from_rosbags(ty, typestore.deserialize_cdr(ours, name)) == decoded
    assert decoded == plain(value)


def test_wstrings_as_the_rmws_write_them(generated: dict[str, Any]) -> None:
    """rosbags has no wstring codec: a count of UTF-16 units, then each unit as a uint32
    (rosidl_typesupport_fastrtps' serialization_helpers.hpp), checked by hand."""
    cls = H.pyclass(generated["test_msgs/msg/WStrings"])
    value = cls(wstring_value="hé😀", array_of_wstrings=["a", "", "b"])
    data = value.serialize()
    units = [0x68, 0xE9, 0xD83D, 0xDE00]
    want = (4).to_bytes(4, "little") + b"".join(u.to_bytes(4, "little") for u in units)
    assert data[4 : 4 + len(want)] == want
    assert cls.deserialize(data) == value


def test_json_hashes_are_counted() -> None:
    total = sum(len(json.loads(f.with_suffix(".json").read_text())["type_hashes"]) for f in IDLS)
    assert total >= 790
