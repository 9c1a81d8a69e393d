"""The AST JSON contract of DESIGN.md: keys per kind, spellings, values, order, docs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from miro_gen.idl import compile_idl
from miro_gen.idl.ast_json import dumps, specifications_json

COMMON = {"kind", "name", "repo_id", "file", "line", "doc", "annotations"}
KEYS = {
    "module": COMMON,
    "forward": COMMON | {"of"},
    "struct": COMMON | {"members", "base"},
    "exception": COMMON | {"members"},
    "union": COMMON | {"discriminator", "cases"},
    "enum": COMMON | {"enumerators"},
    "typedef": COMMON | {"type", "dims"},
    "native": COMMON,
    "const": COMMON | {"type", "value"},
    "interface": COMMON | {"bases", "abstract", "local", "operations", "attributes"},
    "valuetype": COMMON
    | {"bases", "supports", "members", "operations", "factories", "abstract", "custom"}
    | {"truncatable", "attributes"},
    "valuebox": COMMON | {"type"},
}

SOURCE = r"""
#pragma prefix "miro.org"
/// Robot module.
module Robot {
  //! A pose.
  struct Pose { double x; double y; /** heading */ double theta; };
  interface Sensor;
  struct Node;
  typedef sequence<Node> NodeSeq;
  struct Node { long value; NodeSeq children; };
  typedef Pose PoseArray[2][3], SinglePose;
  typedef sequence<Pose, 10> PoseSeq;
  typedef string<30> Name;
  typedef fixed<5, 2> Money;
  native Handle;
  enum Color { RED, GREEN, BLUE };
  const Color FAVOURITE = GREEN;
  const char LETTER = 'x';
  const boolean YES = TRUE;
  const double HALF = 1.0 / 2.0;
  const fixed PRICE = 12.50d;
  const string GREETING = "hello" ", " "world";
  const unsigned long long BIG = 0xFFFFFFFFFFFFFFFF;
  const long NEG = -(1 << 4) % 7;
  union Reading switch (Color) {
    case RED: long red_count;
    case GREEN: case BLUE: @key string colour_name;
  };
  union ByChar switch (char) { case 'a': long a_val; default: short other; };
  exception Failure { string what; long code; };
  exception Empty {};
  interface Sensor {
    attribute long rate;
    readonly attribute Name label, serial;
    Pose latest(out long age, inout PoseSeq history) raises (Failure) context("a", "b*");
    oneway void ping(in string from_where);
  };
  abstract interface Base { void base_op(); };
  local interface Helper : Base {};
  interface Fused : Sensor, Base { any raw(in Object other); };
  valuetype Box long;
  valuetype Item { public long count; private Name tag; factory create(in long count_arg); };
};
#pragma version Robot::Pose 2.1
#pragma ID Robot::Color "LOCAL:color"
"""


@pytest.fixture(scope="module")
def doc(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    path = tmp_path_factory.mktemp("contract") / "Robot.idl"
    path.write_text(SOURCE)
    spec = compile_idl(str(path))
    text = dumps(specifications_json([str(path)], [spec]))
    parsed: dict[str, object] = json.loads(text)
    return parsed


def decls(doc: dict[str, object]) -> dict[str, dict[str, object]]:
    items = doc["declarations"]
    assert isinstance(items, list)
    out: dict[str, dict[str, object]] = {}
    for d in items:
        out.setdefault(d["name"], d)
    return out


def test_keys_per_kind(doc: dict[str, object]) -> None:
    seen_kinds = set()
    for d in doc["declarations"]:  # type: ignore[attr-defined]
        assert set(d) == KEYS[d["kind"]], d["name"]
        seen_kinds.add(d["kind"])
    assert seen_kinds == set(KEYS)


def test_source_order_and_forwards(doc: dict[str, object]) -> None:
    names = [(d["kind"], d["name"]) for d in doc["declarations"]]  # type: ignore[attr-defined]
    assert names[:5] == [
        ("module", "Robot"),
        ("struct", "Robot::Pose"),
        ("forward", "Robot::Sensor"),
        ("forward", "Robot::Node"),
        ("typedef", "Robot::NodeSeq"),
    ]
    d = decls(doc)
    assert d["Robot::Sensor"]["of"] == "interface"
    assert d["Robot::Node"]["of"] == "struct"
    # Both the forward and the full declaration are listed.
    assert [k for k, n in names if n == "Robot::Node"] == ["forward", "struct"]


def test_repository_ids(doc: dict[str, object]) -> None:
    d = decls(doc)
    assert d["Robot"]["repo_id"] == "IDL:miro.org/Robot:1.0"
    assert d["Robot::Pose"]["repo_id"] == "IDL:miro.org/Robot/Pose:2.1"
    assert d["Robot::Color"]["repo_id"] == "LOCAL:color"
    assert d["Robot::Fused"]["repo_id"] == "IDL:miro.org/Robot/Fused:1.0"


def test_type_spellings(doc: dict[str, object]) -> None:
    d = decls(doc)
    assert d["Robot::NodeSeq"]["type"] == "sequence<Robot::Node>"
    assert (d["Robot::PoseArray"]["type"], d["Robot::PoseArray"]["dims"]) == ("Robot::Pose", [2, 3])
    assert (d["Robot::SinglePose"]["type"], d["Robot::SinglePose"]["dims"]) == ("Robot::Pose", [])
    assert d["Robot::PoseSeq"]["type"] == "sequence<Robot::Pose, 10>"
    assert d["Robot::Name"]["type"] == "string<30>"
    assert d["Robot::Money"]["type"] == "fixed<5, 2>"
    assert d["Robot::BIG"]["type"] == "unsigned long long"
    assert d["Robot::PRICE"]["type"] == "fixed"
    sensor = [x for x in doc["declarations"] if x["name"] == "Robot::Sensor"][-1]  # type: ignore[attr-defined]
    latest = sensor["operations"][0]
    assert latest == {
        "name": "latest",
        "oneway": False,
        "returns": "Robot::Pose",
        "params": [
            {"mode": "out", "name": "age", "type": "long"},
            {"mode": "inout", "name": "history", "type": "Robot::PoseSeq"},
        ],
        "raises": ["Robot::Failure"],
        "contexts": ["a", "b*"],
    }
    assert sensor["operations"][1]["oneway"] is True
    assert sensor["attributes"] == [
        {"name": "rate", "type": "long", "readonly": False, "get_raises": [], "set_raises": []},
        {
            "name": "label",
            "type": "Robot::Name",
            "readonly": True,
            "get_raises": [],
            "set_raises": [],
        },
        {
            "name": "serial",
            "type": "Robot::Name",
            "readonly": True,
            "get_raises": [],
            "set_raises": [],
        },
    ]
    fused = d["Robot::Fused"]
    assert fused["bases"] == ["Robot::Sensor", "Robot::Base"]
    assert fused["operations"][0]["returns"] == "any"
    assert fused["operations"][0]["params"][0]["type"] == "Object"
    assert d["Robot::Base"]["abstract"] is True
    assert d["Robot::Helper"]["local"] is True


def test_constant_values(doc: dict[str, object]) -> None:
    d = decls(doc)
    assert d["Robot::FAVOURITE"]["value"] == "Robot::GREEN"  # enumerators live beside their enum
    assert d["Robot::LETTER"]["value"] == "x"
    assert d["Robot::YES"]["value"] is True
    assert d["Robot::HALF"]["value"] == 0.5
    assert d["Robot::PRICE"]["value"] == "12.50"
    assert d["Robot::GREETING"]["value"] == "hello, world"
    assert d["Robot::BIG"]["value"] == 2**64 - 1
    assert d["Robot::NEG"]["value"] == -2  # C truncating division: -16 % 7 == -2


def test_unions(doc: dict[str, object]) -> None:
    d = decls(doc)
    reading = d["Robot::Reading"]
    assert reading["discriminator"] == "Robot::Color"
    assert reading["cases"] == [
        {"labels": ["Robot::RED"], "name": "red_count", "type": "long", "dims": []},
        {
            "labels": ["Robot::GREEN", "Robot::BLUE"],
            "name": "colour_name",
            "type": "string",
            "dims": [],
        },
    ]
    assert d["Robot::ByChar"]["cases"][0]["labels"] == ["a"]
    assert d["Robot::ByChar"]["cases"][1]["labels"] == ["default"]


def test_members_and_annotations(doc: dict[str, object]) -> None:
    d = decls(doc)
    node = [x for x in doc["declarations"] if x["name"] == "Robot::Node"][-1]  # type: ignore[attr-defined]
    assert node["members"][1] == {
        "name": "children",
        "type": "Robot::NodeSeq",
        "dims": [],
        "annotations": [],
    }
    assert node["base"] is None
    assert d["Robot::Empty"]["members"] == []
    item = d["Robot::Item"]
    assert [(m["name"], m["public"]) for m in item["members"]] == [("count", True), ("tag", False)]
    assert item["factories"] == [
        {
            "name": "create",
            "params": [{"mode": "in", "name": "count_arg", "type": "long"}],
            "raises": [],
        }
    ]
    assert d["Robot::Box"]["type"] == "long"


def test_doc_comments(doc: dict[str, object]) -> None:
    d = decls(doc)
    assert d["Robot"]["doc"] == "Robot module."
    assert d["Robot::Pose"]["doc"] == "A pose."
    assert d["Robot::Color"]["doc"] is None


def test_line_and_file(doc: dict[str, object]) -> None:
    d = decls(doc)
    assert d["Robot"]["line"] == 4
    assert d["Robot::Pose"]["line"] == 6
    assert str(d["Robot"]["file"]).endswith("Robot.idl")


def test_shared_include_listed_once(tmp_path: Path) -> None:
    (tmp_path / "Common.idl").write_text("#pragma once\nmodule C { struct T { long x; }; };\n")
    a = tmp_path / "A.idl"
    b = tmp_path / "B.idl"
    a.write_text('#include "Common.idl"\nmodule A { struct U { C::T t; }; };\n')
    b.write_text('#include "Common.idl"\nmodule B { struct V { C::T t; }; };\n')
    specs = [compile_idl(str(a)), compile_idl(str(b))]
    out = specifications_json([str(a), str(b)], specs)
    names = [x["name"] for x in out["declarations"]]
    assert names == ["C", "C::T", "A", "A::U", "B", "B::V"]
    assert out["files"] == [str(a), str(b)]
