"""Generated stubs and skeletons called in process through `LocalInvoker` (real CDR bytes):
every parameter mode and return convention, primitives, octet sequences, bounded values."""

from __future__ import annotations

import inspect
from array import array
from types import SimpleNamespace
from typing import Any

import pytest

from miro_gen.runtime.rpc import Servant, Stub

# =============================================================================================
# parameter modes and return conventions
# =============================================================================================


def test_stub_and_skeleton_classes(gen: SimpleNamespace) -> None:
    Rpc, POA = gen.Rpc, gen.POA
    assert issubclass(Rpc.Modes, Stub) and issubclass(POA.Modes, Servant)
    assert Rpc.Modes._repo_id == POA.Modes._repo_id == "IDL:Rpc/Modes:1.0"
    assert Rpc.Modes.__module__ == "Rpc.Rpc_idl" and POA.Modes.__module__ == "Rpc__POA.Rpc_idl"


def test_void_without_out_returns_none(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.nothing() is None
    assert servant.called("nothing") == [()]


def test_in_parameter_and_single_result(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.set_value(-123456) is None
    assert servant.called("set_value") == [(-123456,)]
    assert stub.get_value() == -123456


def test_single_out_is_returned_alone(modes: tuple[Any, Any]) -> None:
    stub, _ = modes
    assert "v" not in inspect.signature(stub.out_only).parameters  # out: not an argument
    assert stub.out_only() == 42


def test_result_and_outs_are_a_tuple_in_declaration_order(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert list(inspect.signature(stub.result_and_outs).parameters) == ["a"]
    result = stub.result_and_outs(20)
    assert type(result) is tuple
    assert result == (21, 40, "<20>")
    assert servant.called("result_and_outs") == [(20,)]


def test_outs_without_result_are_a_tuple(modes: tuple[Any, Any]) -> None:
    stub, _ = modes
    assert stub.two_outs() == (-5, "two")


def test_result_and_inout_are_a_tuple(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.inout_only("abc") == ("ABC", "cba")
    assert servant.called("inout_only") == [("abc",)]


def test_inout_struct(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    Point = gen.Rpc.Point
    sent = Point(3, -(2**31))
    got = stub.inout_struct(sent)
    assert got == Point(-(2**31), -3) and type(got) is Point
    assert servant.called("inout_struct") == [(Point(3, -(2**31)),)]
    assert sent == Point(3, -(2**31))  # the caller's value is not modified in place


@pytest.mark.parametrize("seq", [[], [7], [1, -2, 2**31 - 1, -(2**31) + 5]])
def test_inout_sequence(modes: tuple[Any, Any], seq: list[int]) -> None:
    stub, servant = modes
    got = stub.inout_seq(seq)
    assert got == array("i", [*seq, sum(seq)])  # numbers arrive as array.array
    assert servant.called("inout_seq") == [(array("i", seq),)]


@pytest.mark.parametrize("text", ["", "x", "héllo wörld ✓", "a" * 1000])
def test_inout_string(modes: tuple[Any, Any], text: str) -> None:
    stub, servant = modes
    assert stub.inout_string(text) == text[::-1] + "!"
    assert servant.called("inout_string") == [(text,)]


@pytest.mark.parametrize("ordinal", [0, 1, 2])
def test_inout_enum(gen: SimpleNamespace, modes: tuple[Any, Any], ordinal: int) -> None:
    stub, servant = modes
    Color = gen.Rpc.Color
    got = stub.inout_enum(Color(ordinal))
    assert got is Color((ordinal + 1) % 3)
    (args,) = servant.called("inout_enum")
    assert args[0] is Color(ordinal)  # arrives as the IntEnum member, not a bare int


def test_inout_union_every_branch(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    Shape, Point = gen.Rpc.Shape, gen.Rpc.Point
    assert stub.inout_union(Shape(count=41)) == Shape(count=42)
    assert stub.inout_union(Shape(name="sq")) == Shape(name="sq?")
    got = stub.inout_union(Shape(where=Point(1, 2)))
    assert got == Shape(where=Point(2, 1)) and got.where == Point(2, 1)
    # the default branch with a discriminator of the caller's choosing keeps it
    got = stub.inout_union(Shape(77, Point(5, 6)))
    assert got._d == 77 and got.where == Point(6, 5)
    received = [args[0] for args in servant.called("inout_union")]
    assert received == [
        Shape(count=41),
        Shape(name="sq"),
        Shape(where=Point(1, 2)),
        Shape(77, Point(5, 6)),
    ]


def test_mixed_modes(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    Point, Color = gen.Rpc.Point, gen.Rpc.Color
    params = inspect.signature(stub.mixed).parameters
    assert list(params) == ["a", "s", "tag", "o"]  # in and inout, in IDL order; no out `c`
    result, seq, color, octet = stub.mixed(Point(1, 2), [Point(9, 9)], "g", 255)
    assert result == Point(2, 3)
    assert seq == [Point(9, 9), Point(1, 2)]
    assert color is Color.GREEN
    assert octet == 0
    assert servant.called("mixed") == [(Point(1, 2), [Point(9, 9)], "g", 255)]


def test_primitives_arrive_exactly(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    args = (
        -(2**15),
        2**16 - 1,
        -(2**31),
        2**32 - 1,
        -(2**63),
        2**64 - 1,
        0.5,
        -1e300,
        True,
        "é",
        255,
    )
    assert stub.prims(*args) == -2e300
    assert servant.called("prims") == [args]
    stub.prims(0, 0, 0, 0, 0, 0, 0.0, 0.0, False, "\0", 0)
    assert servant.called("prims")[1] == (0, 0, 0, 0, 0, 0, 0.0, 0.0, False, "\0", 0)


@pytest.mark.parametrize("data", [b"", b"\x00", bytes(range(256)) * 3])
def test_octet_sequence_is_bytes(modes: tuple[Any, Any], data: bytes) -> None:
    stub, servant = modes
    got = stub.blob(data)
    assert got == data[::-1] and type(got) is bytes
    assert servant.called("blob") == [(data,)]


def test_bounded_values_within_their_bounds(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    stub.bounded("abcde", [1, 2, 3])
    stub.bounded("", [])
    assert servant.called("bounded") == [("abcde", array("i", [1, 2, 3])), ("", array("i"))]
