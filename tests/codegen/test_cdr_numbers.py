"""Sequences and arrays of numbers as `array.array` (DESIGN.md, "Generated Python"): what decoding
gives, what encoding takes, and the checks encoding keeps.

The bytes themselves are checked against Cyclone DDS with random values of every shape (including
the `Numbers` and `NumberTypedefs` structs of tests/codegen/types.idl) by test_cdr_oracle.py, whose
values come as arrays, lists, tuples, numpy arrays and memoryviews (codegen_helpers.values).
"""

from __future__ import annotations

import typing
from array import array
from collections.abc import Callable
from typing import Any

import codegen_helpers as H
import numpy
import pytest

from miro_gen.exceptions import BAD_PARAM

T = H.CodecTest
U = H.CodecUnions


def numbers() -> Any:
    """A Numbers value with every field set, odd lengths included."""
    return T.Numbers(
        lead=1,
        i8s=array("b", [-1, 2, -3]),
        after_i8s=0.5,
        u16s=array("H", [65535]),
        after_u16s=-(2**40),
        floats=array("f", [1.5, -2.25, 3.0, 4.5, 5.0]),
        after_floats=1e300,
        big=array("f", range(17)),
        gap=255,
        bigd=array("d", [i / 4 for i in range(40)]),  # exact as float too
        c="x",
        grid=[array("h", range(k, k + 20)) for k in (0, -100, 1000)],
        small=array("B", [0, 128, 255]),
        pair=[array("h", [1, -1]), array("h", [-32768, 32767])],
        rows=[array("d"), array("d", [1.0]), array("d", [2.0, 3.0])],
        bounded64=array("Q", [2**64 - 1, 0, 7]),
        i64s=array("q", [-(2**63)]),
        tail=-128,
    )


# =============================================================================================
# what decoding gives
# =============================================================================================

SEQUENCE_CODES = {
    "doubles": "d",
    "floats": "f",
    "i8s": "b",
    "u8s": "B",
    "shorts": "h",
    "ushorts": "H",
    "longs": "i",
    "ulongs": "I",
    "llongs": "q",
    "ullongs": "Q",
}


def test_every_integer_and_float_type_has_its_type_code() -> None:
    value = T.Sequences(**{name: [1] for name in SEQUENCE_CODES})
    back = T.Sequences.deserialize(value.serialize())
    for name, code in SEQUENCE_CODES.items():
        got = getattr(back, name)
        assert type(got) is array and got.typecode == code and got == array(code, [1]), name
        assert getattr(T.Sequences(), name) == array(code), name  # the default: empty


def test_arrays_are_arrays_and_their_last_dimension_too() -> None:
    back = T.Numbers.deserialize(numbers().serialize())
    assert back.big == array("f", range(17)) and back.big.typecode == "f"
    assert back.small == array("B", [0, 128, 255])
    assert type(back.grid) is list and [type(r) for r in back.grid] == [array] * 3
    assert back.grid[2] == array("h", range(1000, 1020))
    assert back.pair == [array("h", [1, -1]), array("h", [-32768, 32767])]
    assert back.rows == [array("d"), array("d", [1.0]), array("d", [2.0, 3.0])]
    assert H.plain(back) == H.plain(numbers())
    nested = T.NumberTypedefs.deserialize(T.NumberTypedefs(vs=[[1, 2, 3], [4, 5, 6]]).serialize())
    assert nested.vs == [array("d", [1, 2, 3]), array("d", [4, 5, 6])]
    assert nested.ul == [array("I", [0])] * 20 and nested.i32 == array("i", [0] * 18)
    assert U.Branches.deserialize(U.Branches(floats=[0.5]).serialize()).floats == array("f", [0.5])


def test_default_values_are_zeros_of_the_right_type() -> None:
    v = T.Numbers()
    assert v.big == array("f", [0.0] * 17) and v.bigd.typecode == "d"
    assert v.grid == [array("h", [0] * 20)] * 3 and v.grid[0] is not v.grid[1]
    assert v.i8s == array("b") and v.rows == []
    assert T.Numbers().i8s is not v.i8s  # a new array for each value
    assert U.Branches(v=[1, 2, 3]).v == [1, 2, 3] and U.Branches(d=1)._d == 10


def test_booleans_chars_octets_and_enums_keep_their_mapping() -> None:
    v = T.Sequences(octets=b"ab", flags=[True], chars=["z"], colors=[T.BLUE])
    back = T.Sequences.deserialize(v.serialize())
    assert type(back.octets) is bytes and back.flags == [True] and back.chars == ["z"]
    assert back.colors == [T.BLUE]
    arrays = T.Arrays.deserialize(T.Arrays().serialize())
    assert type(arrays.o5) is list and type(arrays.b3) is list and type(arrays.c4) is list


def test_numpy_views_decoded_numbers_without_a_copy() -> None:
    back = T.Numbers.deserialize(numbers().serialize())
    view = numpy.frombuffer(back.floats, dtype=numpy.float32)
    assert view.tolist() == [1.5, -2.25, 3.0, 4.5, 5.0]
    back.floats[0] = 8.0
    assert view[0] == 8.0  # the same memory
    grid = numpy.array([numpy.frombuffer(row, dtype=numpy.int16) for row in back.grid])
    assert grid.shape == (3, 20) and grid[1, 1] == -99


def test_annotations_evaluate() -> None:
    """`array.array[int]` cannot be subscripted on Python 3.11: the annotation is spelled so that
    typedef aliases and typing.get_type_hints() work there too."""
    hints = typing.get_type_hints(T.Numbers)
    assert typing.get_origin(hints["floats"]) is array
    assert typing.get_args(hints["floats"]) == (float,)
    assert typing.get_origin(T.Floats8) is array
    assert typing.get_origin(typing.get_type_hints(T.NumberTypedefs)["vs"]) is list


# =============================================================================================
# what encoding takes
# =============================================================================================


class NoIteration(numpy.ndarray):  # type: ignore[type-arg]
    """A numpy array that refuses to be read element by element."""

    def __iter__(self) -> Any:
        raise AssertionError("read element by element")

    def __getitem__(self, key: Any) -> Any:
        raise AssertionError("read element by element")


def _np(values: list[Any], code: str) -> Any:
    return numpy.array(values, dtype=numpy.dtype(code))


# Another item type that holds the same values (a wider one: converted element by element).
OTHER = {"f": "d", "d": "f", "b": "q", "B": "q", "h": "q", "H": "q", "Q": ""}


def _other(convert: Callable[[list[Any], str], Any]) -> Callable[[list[Any], str], Any]:
    return lambda v, code: convert(v, OTHER[code]) if OTHER[code] else v


# name -> how a list of numbers of array type code `code` is given
INPUTS: dict[str, Callable[[list[Any], str], Any]] = {
    "list": lambda v, code: v,
    "tuple": lambda v, code: tuple(v),
    "array.array": lambda v, code: array(code, v),
    "array.array of another type": _other(lambda v, code: array(code, v)),
    "numpy array": _np,
    "numpy, not read element by element": lambda v, code: _np(v, code).view(NoIteration),
    "numpy, not contiguous": lambda v, code: numpy.repeat(_np(v, code), 2)[::2],
    "numpy, big-endian": lambda v, code: _np(v, code).astype(numpy.dtype(code).newbyteorder(">")),
    "numpy of another type": _other(_np),
    "memoryview": lambda v, code: memoryview(array(code, v)),
}
# Inputs read through the buffer protocol only: not for the short arrays packed with others.
BUFFER_ONLY = {"numpy, not read element by element"}


@pytest.mark.parametrize("given", list(INPUTS), ids=list(INPUTS))
def test_any_sequence_or_buffer_of_numbers_encodes_the_same(given: str) -> None:
    make = INPUTS[given]
    expected = numbers().serialize()
    v = numbers()
    v.i8s = make([-1, 2, -3], "b")
    v.floats = make([1.5, -2.25, 3.0, 4.5, 5.0], "f")
    v.big = make(list(range(17)), "f")
    v.bigd = make([i / 4 for i in range(40)], "d")
    v.grid = [make(list(range(k, k + 20)), "h") for k in (0, -100, 1000)]
    if given not in BUFFER_ONLY:
        v.small = make([0, 128, 255], "B")
    v.bounded64 = make([2**64 - 1, 0, 7], "Q")
    assert v.serialize() == expected


def test_a_multidimensional_buffer_is_its_elements_in_row_order() -> None:
    image = numpy.arange(4 * 5 * 3, dtype=numpy.uint8).reshape(4, 5, 3)
    data = T.Sequences(u8s=image).serialize()
    assert T.Sequences.deserialize(data).u8s == array("B", range(60))
    grid = numpy.arange(60, dtype=numpy.int16).reshape(3, 20)
    assert T.Numbers(grid=grid).serialize() == T.Numbers(grid=grid.tolist()).serialize()
    flat = T.Sequences(u8s=bytes(range(60))).serialize()
    assert flat == data == T.Sequences(u8s=bytearray(range(60))).serialize()


def test_large_sequences_round_trip_from_any_buffer() -> None:
    pixels = numpy.random.default_rng(1).integers(0, 256, 10 << 20, dtype=numpy.uint8)
    ranges = numpy.linspace(0.0, 30.0, 1 << 20, dtype=numpy.float32)
    data = T.Sequences(u8s=pixels, floats=ranges).serialize()
    for given in (data, bytearray(data), memoryview(data)):
        back = T.Sequences.deserialize(given)
        assert numpy.array_equal(numpy.frombuffer(back.u8s, numpy.uint8), pixels)
        assert numpy.array_equal(numpy.frombuffer(back.floats, numpy.float32), ranges)


# (what, the value, the field the message names)
OUT_OF_RANGE: list[tuple[str, Callable[[], Any], str]] = [
    ("int64 too big for long", lambda: T.Sequences(longs=_np([2**40], "q")), "longs"),
    ("negative into unsigned", lambda: T.Sequences(ulongs=_np([-1], "i")), "ulongs"),
    ("uint8 into int8", lambda: T.Sequences(i8s=bytes([200])), "i8s"),
    ("float64 overflows float", lambda: T.Sequences(floats=_np([1e39], "d")), "floats"),
    ("overflow in a bulk array", lambda: T.Numbers(big=array("d", [1e39] * 17)), "big"),
    ("floats where integers go", lambda: T.Sequences(longs=_np([1.5], "f")), "longs"),
    ("bulk array too short", lambda: T.Numbers(big=_np([1.0] * 16, "f")), "big"),
    ("bulk array too long", lambda: T.Numbers(bigd=array("d", [0.0] * 41)), "bigd"),
    ("a row of a bulk 2-D array", lambda: T.Numbers(grid=[array("h")] * 3), "grid"),
    ("over the bound", lambda: T.Numbers(bounded64=_np([1, 2, 3, 4], "Q")), "bounded64"),
    ("a numpy scalar", lambda: T.Sequences(floats=numpy.float32(1.0)), "floats"),
    ("a 2-D buffer of another type", lambda: T.Sequences(u8s=numpy.ones((2, 2))), "u8s"),
    ("not numbers at all", lambda: T.Sequences(doubles="abc"), "doubles"),
    ("None", lambda: T.Numbers(big=None), "big"),
]


@pytest.mark.parametrize(
    ("make", "field"),
    [(m, f) for _, m, f in OUT_OF_RANGE],
    ids=[w for w, _, _ in OUT_OF_RANGE],
)
def test_numbers_that_do_not_fit_are_bad_param_naming_the_field(
    make: Callable[[], Any], field: str
) -> None:
    value = make()
    with pytest.raises(BAD_PARAM) as info:
        value.serialize()
    assert f"{value._type_name}.{field}" in str(info.value)


def test_large_payloads_set_aside_keep_the_alignment_of_what_follows() -> None:
    """From 64 KiB on, payloads are joined in at the end rather than copied in (cdr.Encoder):
    the bytes are Cyclone's, with odd sizes before aligned values."""
    rng = numpy.random.default_rng(2)
    values = [
        T.Numbers(
            i8s=rng.integers(-128, 128, 65537, dtype=numpy.int8),
            after_i8s=0.5,
            u16s=array("H", range(40001)),
            floats=rng.random(20001, dtype=numpy.float32),
            rows=[array("d", [1.0]), array("d", rng.random(9000)), array("d")],
            i64s=array("q", [7]),
            tail=-1,
        ),
        T.Sequences(
            octets=rng.bytes(70001),
            points=[T.Point(float(i), -float(i)) for i in range(5001)],
            blobs=[b"x", rng.bytes(66000), b""],
            doubles=[0.25],
        ),
    ]
    for value in values:
        decl = H.specification()[value._type_name]
        theirs = H.cyclone().value(H.resolve(decl), value).serialize()
        assert value.serialize() == theirs
        assert H.plain(type(value).deserialize(theirs)) == H.plain(value)


def test_a_value_encoded_after_a_head_is_aligned_as_alone() -> None:
    """What the transport puts a large event's frame together with (cdr.encode_after)."""
    from miro_gen.runtime.cdr import encode_after

    for value in (numbers(), T.Numbers(i8s=bytes(70001), floats=array("f", [1.0] * 20001))):
        head = b"H" * 72
        buf = encode_after(head, value)
        assert buf.size == 72 + len(value.serialize())
        buf.overwrite(3, b"xy")
        assert buf.value() == b"HHHxy" + head[5:] + value.serialize()
    with pytest.raises(ValueError, match="misalign"):
        encode_after(b"12345", numbers())
