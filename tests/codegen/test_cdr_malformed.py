"""Malformed CDR: decoding must fail with MARSHAL at once, never with another exception, never
after much work or a big allocation.

Covered, on the types of tests/codegen/*.idl: every truncation of encoded values; wrong and XCDR2
encapsulation headers; sequence and string lengths that are 0xFFFFFFFF or larger than the bytes
left (with the Python steps and the peak of traced allocations of each decoding bounded);
strings without their NUL or not UTF-8; bounds exceeded on the wire; enum values and enum
discriminators out of range; random bytes and random mutations of valid encodings, for every
type; data nested deeper than Python recursion.

Truncation: our encoder writes no trailing bytes and the decoder reads every byte it is given up
to the last field, so a strict prefix of an encoding is never a complete encoding; a prefix that
decodes anyway must at least be the encoding of what it decodes to (checked by re-encoding).

Tests marked `xfail(strict=True, reason="bug: ...")` document bugs found while writing these.
"""

from __future__ import annotations

import struct
import sys
import tracemalloc
from array import array
from collections.abc import Iterator
from types import FrameType
from typing import Any

import codegen_helpers as H
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from miro_gen.exceptions import BAD_PARAM, MARSHAL

T = H.CodecTest
U = H.CodecUnions

TYPES = H.data_types()
IDS = [d.scoped_name for d in TYPES]
LE = b"\x00\x01\x00\x00"
BE = b"\x00\x00\x00\x00"
# Work, counted rather than timed (a loaded machine only slows it): the most any one value may
# cost is its cap of 65536 empty elements, about 9 traced Python steps (calls and lines) each;
# a length taken on trust would run for billions of steps and allocate without end.
MAX_STEPS = 1_000_000
MAX_PEAK = 10 * 1024 * 1024

SETTINGS = settings(H.SETTINGS, max_examples=8)


def decode(cls: Any, data: bytes) -> Any:
    """The decoded value, or None for MARSHAL; anything else fails the test."""
    try:
        return cls.deserialize(data)
    except MARSHAL:
        return None


class TooMuchWork(BaseException):
    """Raised inside the decoder once it passes MAX_STEPS (a BaseException, so that no
    `except Exception` in the decoder can turn it into MARSHAL)."""


def decode_quickly(cls: Any, data: bytes) -> Any:
    """`decode`, with its Python steps and the peak of its Python allocations bounded."""
    steps = 0

    def count(frame: FrameType, event: str, arg: Any) -> Any:
        nonlocal steps
        steps += 1
        if steps > MAX_STEPS:
            raise TooMuchWork(f"{cls._type_name}: over {MAX_STEPS} steps for {len(data)} bytes")
        return count

    before = sys.gettrace()
    tracemalloc.start()
    sys.settrace(count)
    try:
        value = decode(cls, data)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        sys.settrace(before)
        tracemalloc.stop()
    assert peak < MAX_PEAK, f"{cls._type_name}: {peak} bytes allocated for {len(data)} bytes"
    return value


def u32(value: int) -> bytes:
    return struct.pack("<I", value)


def cdr_string(buf: bytes, text: bytes) -> bytes:
    """`buf` with a string appended (aligned length, bytes, NUL); `buf` starts with the header."""
    buf += bytes(-(len(buf) - 4) % 4)
    return buf + u32(len(text) + 1) + text + b"\x00"


# =============================================================================================
# truncation
# =============================================================================================


def check_truncations(cls: Any, data: bytes) -> None:
    for k in range(len(data)):
        prefix = data[:k]
        value = decode(cls, prefix)
        if value is not None:
            assert value.serialize() == prefix, (
                f"{cls._type_name}: the first {k} of {len(data)} bytes decode to {value!r}"
            )


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_truncated_default_value(decl: Any) -> None:
    cls = H.pyclass(decl)
    check_truncations(cls, cls().serialize())


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
@SETTINGS
@given(data=st.data())
def test_truncated_value(decl: Any, data: st.DataObject) -> None:
    value = data.draw(H.values(H.resolve(decl)))
    check_truncations(H.pyclass(decl), value.serialize())


def test_truncated_big_endian() -> None:
    from cyclonedds.idl._support import Endianness

    for name, value in [
        ("CodecTest::Primitives", T.Primitives(1, 2, 3, 4, 5, 6, 7, 8, 9, "x", True, 1.0, 2.0)),
        ("CodecTest::Sequences", T.Sequences(longs=[1, 2], strings=["ab"], points=[T.Point()])),
        ("CodecUnions::Holder", U.Holder(b=U.Branches(ps=[T.Point(1, 2)]), many=[U.ByChar()])),
    ]:
        decl = H.specification()[name]
        big = H.cyclone().value(H.resolve(decl), value).serialize(endianness=Endianness.Big)
        assert H.plain(H.pyclass(decl).deserialize(big)) == H.plain(value)
        check_truncations(H.pyclass(decl), big)


def test_empty_struct_is_the_header_alone() -> None:
    assert T.Empty.deserialize(LE) == T.Empty()
    assert T.Nothing.deserialize(BE).serialize() == LE
    for k in range(4):
        with pytest.raises(MARSHAL):
            T.Empty.deserialize(LE[:k])


# =============================================================================================
# encapsulation header
# =============================================================================================

BAD_HEADERS = [
    b"\x01\x01\x00\x00",
    b"\x01\x00\x00\x00",
    b"\x00\x02\x00\x00",  # PL_CDR_BE (XCDR1 parameter list)
    b"\x00\x03\x00\x00",  # PL_CDR_LE
    b"\x00\x06\x00\x00",  # CDR2_BE
    b"\x00\x07\x00\x00",  # CDR2_LE
    b"\x00\x08\x00\x00",  # D_CDR2_BE
    b"\x00\x09\x00\x00",  # D_CDR2_LE
    b"\x00\x0a\x00\x00",  # PL_CDR2_BE
    b"\x00\x0b\x00\x00",  # PL_CDR2_LE
    b"\x00\x10\x00\x00",
    b"\xff\xff\x00\x00",
]


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_wrong_header(decl: Any) -> None:
    cls = H.pyclass(decl)
    body = cls().serialize()[4:]
    for header in BAD_HEADERS:
        with pytest.raises(MARSHAL):
            cls.deserialize(header + body)
    for short in (b"", b"\x00", b"\x00\x01", b"\x00\x01\x00"):
        with pytest.raises(MARSHAL):
            cls.deserialize(short)


def test_xcdr2_is_named_in_the_error() -> None:
    with pytest.raises(MARSHAL, match="XCDR2"):
        T.Point.deserialize(b"\x00\x07\x00\x00" + bytes(16))


# =============================================================================================
# lying lengths
# =============================================================================================


def sequence_offsets() -> Iterator[tuple[str, int]]:
    """Sequences() is nothing but empty sequences: the length of member i is at 4 + 4 i."""
    names = H.fields_of(H.specification()["CodecTest::Sequences"])
    data = T.Sequences().serialize()
    assert data == LE + bytes(4 * len(names))
    for i, name in enumerate(names):
        yield name, 4 + 4 * i


SEQUENCE_OFFSETS = list(sequence_offsets())


@pytest.mark.parametrize(
    ("member", "offset"), SEQUENCE_OFFSETS, ids=[m for m, _ in SEQUENCE_OFFSETS]
)
def test_sequence_length_beyond_the_data(member: str, offset: int) -> None:
    data = T.Sequences().serialize()
    left = len(data) - offset - 4
    for claim in (0xFFFFFFFF, 0x7FFFFFFF, 1 << 24, left + 1):
        lying = data[:offset] + u32(claim) + data[offset + 4 :]
        assert decode_quickly(T.Sequences, lying) is None, f"{member} claims {claim}"


def test_string_length_beyond_the_data() -> None:
    data = T.Strings().serialize()
    assert data == LE + (u32(1) + bytes(4)) * 4 + u32(1) + b"\x00"  # five empty strings
    for offset in range(4, len(data), 8):
        left = len(data) - offset - 4
        for claim in (0xFFFFFFFF, 0x80000000, left + 1, left + 2):
            lying = data[:offset] + u32(claim) + data[offset + 4 :]
            assert decode_quickly(T.Strings, lying) is None, (offset, claim)


def test_nested_lengths_beyond_the_data() -> None:
    """Lengths inside sequences, arrays, unions and recursive types (the word at `index` of
    the unique `marker`)."""
    cases = [
        (T.Sequences(nested=[[1, 2]]), u32(1) + u32(2), 1),
        (T.Sequences(strings=["abc"]), u32(1) + u32(4), 1),
        (T.Sequences(blobs=[b"xy"]), u32(1) + u32(2), 1),
        (T.Sequences(point_rows=[[T.Point()]]), u32(1) + u32(1), 1),
        (U.Branches(ps=[T.Point()]), u32(2) + u32(1), 1),
        (U.Branches(raw=b"abc"), u32(8) + u32(3), 1),
        (T.Node(1, [T.Node(2, [T.Node(3, [])])]), u32(2) + u32(1), 1),
        (T.Arrays(sa=[[5], []]), u32(1) + u32(5), 0),
        (U.Holder(many=[U.ByChar(other="abc")]), u32(1) + b"\x00" + bytes(3) + u32(4), 2),
    ]
    for value, marker, index in cases:
        data = value.serialize()
        at = data.index(marker) + 4 * index
        for claim in (0xFFFFFFFF, len(data) - at):
            lying = replace_word(data, marker, index, claim)
            assert decode_quickly(type(value), lying) is None, (value, claim)


def scan_values(decl: Any) -> list[Any]:
    cls = H.pyclass(decl)
    values = [cls()]

    @settings(SETTINGS, max_examples=3)
    @given(H.values(H.resolve(decl)))
    def collect(v: Any) -> None:
        values.append(v)

    collect()
    return values


SCANNED = [d for d in TYPES if d.scoped_name != "CodecTest::EmptyRows"]


@pytest.mark.parametrize("decl", SCANNED, ids=[d.scoped_name for d in SCANNED])
def test_every_word_as_a_huge_length(decl: Any) -> None:
    """Each aligned 32-bit word of valid encodings, set to a huge value or to one more than the
    bytes after it: MARSHAL or a value, quickly, without a big allocation."""
    cls = H.pyclass(decl)
    for value in scan_values(decl):
        data = value.serialize()
        for offset in range(4, len(data) - 3, 4):
            left = len(data) - offset - 4
            for claim in (0xFFFFFFFF, 0x10000000, left + 1):
                lying = data[:offset] + u32(claim) + data[offset + 4 :]
                decode_quickly(cls, lying)


def test_zero_size_elements_are_capped() -> None:
    """A sequence of empty structs takes no bytes, so its length cannot be checked against
    the data; a huge claim is still refused."""
    data = T.HasEmpty(c="x").serialize()
    assert data[-4:] == bytes(4)
    assert decode_quickly(T.HasEmpty, data[:-4] + u32(0xFFFFFFFF)) is None
    assert decode_quickly(T.HasEmpty, data[:-4] + u32(1 << 24)) is None
    assert len(decode_quickly(T.HasEmpty, data[:-4] + u32(1000)).seq) == 1000


def test_nested_zero_size_elements_do_not_amplify() -> None:
    """The cap counts every empty element of one value, however they are nested: 16 rows of
    65536 are refused, 16 rows of 4096 (65536 in all) are decoded."""
    assert decode_quickly(T.EmptyRows, LE + u32(16) + u32(65536) * 16) is None
    rows = decode(T.EmptyRows, LE + u32(16) + u32(4096) * 16).rows
    assert [len(row) for row in rows] == [4096] * 16


# =============================================================================================
# strings, enums, bounds
# =============================================================================================


def test_string_without_nul() -> None:
    cases = [
        (T.Strings(plain="abc"), b"abc\x00"),
        (T.Strings(bounded="abcde"), b"abcde\x00"),
        (T.Sequences(strings=["", "xyz"]), b"xyz\x00"),
        (U.ByChar(other="qq"), b"qq\x00"),
        (T.Arrays(s2=["k", "lm"]), b"lm\x00"),
        (T.Derived(3, "name"), b"name\x00"),
    ]
    for value, text in cases:
        data = value.serialize()
        at = data.index(text) + len(text) - 1
        for bad in (b"x", b"\x01", b"\xff"):
            assert decode_quickly(type(value), data[:at] + bad + data[at + 1 :]) is None, value


def test_string_with_a_nul_inside() -> None:
    data = cdr_string(LE, b"a\x00b")
    data = cdr_string(cdr_string(cdr_string(cdr_string(data, b""), b""), b""), b"")
    with pytest.raises(MARSHAL):
        T.Strings.deserialize(data)


def test_string_not_utf8() -> None:
    for bad in (b"\xff", b"\xc3", b"\xc0\x80", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80"):
        data = LE + u32(len(bad) + 1) + bad + b"\x00"
        data = cdr_string(cdr_string(cdr_string(cdr_string(data, b""), b""), b""), b"")
        assert decode_quickly(T.Strings, data) is None, bad
    good = cdr_string(LE, "\xe9\u20ac".encode())
    good = cdr_string(cdr_string(cdr_string(cdr_string(good, b""), b""), b""), b"")
    assert T.Strings.deserialize(good).plain == "\xe9\u20ac"


def test_string_over_its_bound_on_the_wire() -> None:
    def strings(bounded: bytes) -> bytes:
        data = cdr_string(cdr_string(LE, b""), bounded)
        return cdr_string(cdr_string(cdr_string(data, b""), b""), b"")

    assert T.Strings.deserialize(strings(b"abcde")).bounded == "abcde"
    assert decode_quickly(T.Strings, strings(b"abcdef")) is None
    # The bound counts bytes: two two-byte characters do not fit string<3>.
    seq = T.Sequences(bounded_strings=["ab"]).serialize()
    at = seq.index(u32(1) + u32(3) + b"ab\x00")
    over = seq[:at] + u32(1) + u32(5) + "\xe9\xe9".encode() + b"\x00" + seq[at + 11 :]
    assert decode_quickly(T.Sequences, over) is None


def test_sequence_over_its_bound_on_the_wire() -> None:
    names = H.fields_of(H.specification()["CodecTest::Sequences"])
    assert names[1] == "bounded"
    rest = bytes(4 * (len(names) - 2))
    ok = LE + u32(0) + u32(5) + struct.pack("<5i", *range(5)) + rest
    assert T.Sequences.deserialize(ok).bounded == array("i", [0, 1, 2, 3, 4])
    over = LE + u32(0) + u32(6) + struct.pack("<6i", *range(6)) + rest
    assert decode_quickly(T.Sequences, over) is None
    octets = T.Sequences(octets4=b"abcd").serialize()
    at = octets.index(u32(4) + b"abcd")
    over = octets[:at] + u32(5) + b"abcde" + octets[at + 8 :]
    assert decode_quickly(T.Sequences, over) is None


def replace_word(data: bytes, marker: bytes, index: int, value: int) -> bytes:
    """`data` with the `index`-th 32-bit word of the (unique) `marker` replaced."""
    assert data.count(marker) == 1, marker
    at = data.index(marker) + 4 * index
    return data[:at] + u32(value) + data[at + 4 :]


ENUM_CASES: list[tuple[str, Any, bytes, int]] = [
    ("enum field", T.Enums(T.BLUE, T.ONLY, T.Words._mro), u32(2) + u32(0) + u32(4), 0),
    ("single-enumerator enum", T.Enums(T.BLUE, T.ONLY, T.Words._mro), u32(2) + u32(0), 1),
    ("enum in a sequence", T.Sequences(colors=[T.RED, T.BLUE]), u32(2) + u32(0) + u32(2), 2),
    ("enum in an array", T.Arrays(e3=[T.GREEN, T.GREEN, T.BLUE]), u32(1) + u32(1) + u32(2), 2),
    ("enum in a 2-D array", T.Arrays(em=[[T.RED, T.RED], [T.BLUE, T.BLUE]]), u32(2) * 2, 1),
    ("enum in a union", U.Branches(c=T.BLUE), u32(5) + u32(2), 1),
    ("enum discriminator", U.ByEnum(gb="x"), u32(1) + u32(2), 0),
    ("enum discriminator, default", U.ByEnumDefault(g=3), LE + u32(1), 1),
    ("enum discriminator, partial", U.ByEnumPartial(r=1), LE + u32(0), 1),
    ("typedef'd enum discriminator", U.ByTypedefEnum(r=1), LE + u32(0), 1),
    ("nested union", T.Outer(choice=T.Holder_Choice(when_off=77)), u32(0) + u32(77), 0),
    ("enum in a typedef", T.Typedefs(c=T.BLUE), u32(2), 0),
]


@pytest.mark.parametrize(
    ("value", "marker", "index"),
    [(v, m, i) for _, v, m, i in ENUM_CASES],
    ids=[n for n, _, _, _ in ENUM_CASES],
)
def test_enum_out_of_range(value: Any, marker: bytes, index: int) -> None:
    data = value.serialize()
    cls = type(value)
    assert H.plain(cls.deserialize(data)) == H.plain(value)
    for bad in (3, 5, 0x7FFFFFFF, 0xFFFFFFFF):
        assert decode_quickly(cls, replace_word(data, marker, index, bad)) is None, bad


def test_discriminator_matching_no_label_is_not_an_error() -> None:
    assert U.ByOctet.deserialize(LE + b"\x07")._v is None
    assert U.ByShort.deserialize(LE + b"\x64\x00" + bytes(2) + u32(2) + b"x\x00").other == "x"
    assert U.ByBoolTrue.deserialize(LE + b"\x00")._v is None


# =============================================================================================
# random input
# =============================================================================================


def check_reencodes(cls: Any, value: Any) -> None:
    """What decodes encodes again, to bytes that decode to the same bytes. (A string with a
    NUL inside is let through by the decoder: test_string_with_a_nul_inside, a known bug.)"""
    if value is None:
        return
    try:
        again = value.serialize()
    except BAD_PARAM as e:
        assert "NUL" in str(e), e
        return
    assert cls.deserialize(again).serialize() == again


@pytest.mark.parametrize("decl", SCANNED, ids=[d.scoped_name for d in SCANNED])
@settings(SETTINGS, max_examples=40)
@given(header=st.sampled_from([LE, BE]), body=st.binary(max_size=160))
def test_random_bytes(decl: Any, header: bytes, body: bytes) -> None:
    cls = H.pyclass(decl)
    check_reencodes(cls, decode(cls, header + body))


@pytest.mark.parametrize("decl", SCANNED, ids=[d.scoped_name for d in SCANNED])
@settings(SETTINGS, max_examples=25)
@given(data=st.data())
def test_mutated_encodings(decl: Any, data: st.DataObject) -> None:
    cls = H.pyclass(decl)
    encoded = bytearray(data.draw(H.values(H.resolve(decl))).serialize())
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(4, max(4, len(encoded) - 1)))
        if at < len(encoded):
            encoded[at] = data.draw(st.sampled_from([0, 1, 0x7F, 0x80, 0xFF]))
    check_reencodes(cls, decode(cls, bytes(encoded)))


@pytest.mark.parametrize("kind", ["struct", "union"])
def test_deep_nesting_is_marshal(kind: str) -> None:
    levels = 50_000
    if kind == "struct":  # Node: value, one child, ...
        data = LE + (struct.pack("<iI", 1, 1) * levels) + struct.pack("<iI", 1, 0)
        cls = T.Node
    else:  # Expr: items of one item, ..., leaf
        data = LE + (struct.pack("<iI", 1, 1) * levels) + struct.pack("<ii", 0, 5)
        cls = T.Expr
    try:
        cls.deserialize(data)
    except MARSHAL:
        return
    except RecursionError:  # reported briefly: its full traceback takes pytest half a minute
        pytest.fail("RecursionError", pytrace=False)
    pytest.fail(f"{levels} levels decoded")
