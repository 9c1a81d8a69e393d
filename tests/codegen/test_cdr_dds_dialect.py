"""The DDS / ROS 2 dialect (`miro-idl --case-sensitive`) against PyPI cyclonedds, the oracle.

tests/codegen/dds/ holds IDL in the forms DDS and ROS 2 users have: ros2/ as ROS 2's rosidl
writes it from .msg/.srv/.action files (nested `module pkg { module msg {...} }`, one file per
type including the others by `"pkg/msg/Type.idl"`, `@verbatim` comments, `@default`, `@unit`,
`..._Constants` modules, typedef'd arrays, `sequence<uint8>`, bounded strings and sequences, a
member named `sequence`, a struct named `String`), and shapes/ in DDS style (`Color color;`,
`Header header;`, members `x` and `X`, `@key`). Every file is compiled with --case-sensitive (as
Cyclone's `idlc -f case-sensitive` would) into a temporary folder; the generated Python passes
ruff and mypy --strict, and for every struct and union our `serialize()` equals Cyclone's byte
for byte, each side decoding the other's bytes to the value it started from.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import codegen_helpers as H
import generated_checks as G
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from miro_gen.idl import compile_idl

DDS = H.CODEGEN / "dds"
ROS2 = DDS / "ros2"
FILES = sorted(DDS.rglob("*.idl"))
SPECS = [compile_idl(str(f), [str(ROS2)], case_sensitive=True) for f in FILES]
TYPES = H.data_types_of(SPECS)
IDS = [d.scoped_name for d in TYPES]
SETTINGS = settings(H.SETTINGS, max_examples=25)


@pytest.fixture(scope="module", autouse=True)
def generated(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    out = tmp_path_factory.mktemp("dds") / "out"
    args = ["--case-sensitive", "-I", str(ROS2), "-o", str(out), *map(str, FILES)]
    r = H.run_miro_idl(*args)
    assert r.returncode == 0, r.stderr
    sys.path.insert(0, str(out))
    try:
        with H.registered(SPECS):
            yield out
    finally:
        sys.path.remove(str(out))


def test_files_and_types() -> None:
    assert len(FILES) >= 10
    assert {
        "std_msgs::msg::Header",
        "std_msgs::msg::String",
        "sensor_msgs::msg::BatteryState",
        "action_tutorials_interfaces::action::Fibonacci_Result",
        "shapes::ShapeType",
        "shapes::Size",
    } <= set(IDS)


def test_case_sensitive_is_needed() -> None:
    """Without --case-sensitive these files are CORBA IDL errors, as in omniidl."""
    r = H.run_miro_idl("--ast-json", "-I", str(ROS2), str(DDS / "shapes" / "Shapes.idl"))
    assert r.returncode == 1
    assert "member 'X' clashes with member 'x'" in r.stderr
    assert "declaration of member 'color' clashes with the earlier use of 'Color'" in r.stderr


def test_generated_code_imports_and_passes_ruff_and_mypy_strict(generated: Path) -> None:
    assert not G.import_problems(generated)
    assert not G.ruff_problems(generated)
    assert not G.mypy_problems(generated, generated.parent / "mypy-cache")


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_default_values_match_cyclone(decl: Any) -> None:
    H.check_against_cyclone(decl, H.pyclass(decl)())


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
@SETTINGS
@given(data=st.data())
def test_values_match_cyclone(decl: Any, data: st.DataObject) -> None:
    H.check_against_cyclone(decl, data.draw(H.values(H.resolve(decl), oracle=True)))


def test_ros2_names_and_constants() -> None:
    """What a ROS 2 user writes: the package per module, the `_Constants` module, the field
    named `sequence`, `String` as a class name."""
    import action_tutorials_interfaces.action as action
    import sensor_msgs.msg as msg
    import sensor_msgs.msg.BatteryState_Constants as constants
    import std_msgs.msg as std

    assert constants.POWER_SUPPLY_STATUS_CHARGING == 1
    assert constants.DEFAULT_LOCATION == 'slot "A"'
    assert action.Fibonacci_Result(sequence=[0, 1, 1, 2]).sequence == [0, 1, 1, 2]
    assert std.String(data="hi").data == "hi"
    state = msg.BatteryState(voltage=3.5, cell_voltage=[3.5, 3.6], serial_number="SN-1")
    back = msg.BatteryState.deserialize(state.serialize())
    assert (back.voltage, back.serial_number) == (3.5, "SN-1")
