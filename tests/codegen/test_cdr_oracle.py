"""Our CDR against PyPI cyclonedds, the oracle: the same bytes for the same type and value.

The Cyclone classes are made from the resolved AST of tests/codegen/*.idl (codegen_helpers.py:
`Cyclone`), and the values from hypothesis strategies made from the same AST; each value is
converted to Cyclone's (`Cyclone.value`). For every struct, union and exception Cyclone can
represent, our `serialize()` equals Cyclone's byte for byte, and each side decodes the other's
bytes to the value it started from.

Where Cyclone differs from our contract (and so the strategies keep away): its `char` is packed
signed, so chars of 128 and above fail there (values here use ASCII); it bounds `string<N>` in
characters, we in UTF-8 bytes; it cannot make a boolean union whose two labels are both used and
that has no default; and it picks other default-branch discriminators for enums and for chars
when a label is '\\0' (see test_cdr_codec.py::test_default_discriminator_matches_cyclone).
"""

from __future__ import annotations

from typing import Any

import codegen_helpers as H
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

T = H.CodecTest
U = H.CodecUnions

CYCLONE_CANNOT = {"CodecUnions::ByBool"}
TYPES = [d for d in H.data_types() if d.scoped_name not in CYCLONE_CANNOT]
IDS = [d.scoped_name for d in TYPES]

SETTINGS = settings(H.SETTINGS, max_examples=30)


def test_cyclone_represents_every_type_but_one() -> None:
    cannot = set()
    for d in H.data_types():
        try:
            H.cyclone().cls(d)
        except TypeError as e:
            assert "No space in discriminated union" in str(e)
            cannot.add(d.scoped_name)
    assert cannot == CYCLONE_CANNOT
    assert len(TYPES) >= 50


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_typenames(decl: Any) -> None:
    assert H.cyclone().cls(decl).__idl_typename__ == decl.scoped_name


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_default_values_match_cyclone(decl: Any) -> None:
    H.check_against_cyclone(decl, H.pyclass(decl)())


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
@SETTINGS
@given(data=st.data())
def test_values_match_cyclone(decl: Any, data: st.DataObject) -> None:
    H.check_against_cyclone(decl, data.draw(H.values(H.resolve(decl), oracle=True)))


def test_extreme_values_match_cyclone() -> None:
    lo = T.Primitives(-(2**15), 0, -(2**31), 0, -(2**63), 0, -128, 0, 0, "\x00", False)
    hi = T.Primitives(2**15 - 1, 2**16 - 1, 2**31 - 1, 2**32 - 1, 2**63 - 1, 2**64 - 1, 127)
    hi.u8, hi.o, hi.c, hi.b, hi.f, hi.d = 255, 255, "\x7f", True, 3.4028234663852886e38, 1e308
    decl = H.specification()["CodecTest::Primitives"]
    H.check_against_cyclone(decl, lo)
    H.check_against_cyclone(decl, hi)
    for d, v in [
        ("CodecUnions::ByULongLong", U.ByULongLong(max=1.0)),
        ("CodecUnions::ByLong", U.ByLong(min=-(2**31))),
        ("CodecUnions::ByULong", U.ByULong(max="m")),
        ("CodecUnions::ByUShort", U.ByUShort(max=-1)),
        ("CodecUnions::ByOctet", U.ByOctet(max=2.0)),
        ("CodecUnions::ByLongLong", U.ByLongLong(max=5)),
        ("CodecUnions::ByEnumPartial", U.ByEnumPartial(T.GREEN, None)),
        ("CodecUnions::ByBoolTrue", U.ByBoolTrue(False, None)),
    ]:
        H.check_against_cyclone(H.specification()[d], v)


def test_hand_written_cyclone_classes_agree() -> None:
    """The AST-made Cyclone classes are what one writes by hand (a check of the converter).
    (Written with make_idl_*: this module's annotations are strings, which Cyclone cannot
    read in class bodies.)"""
    from cyclonedds.idl import make_idl_struct, make_idl_union
    from cyclonedds.idl.types import byte, case, char, default, float64, int32

    mixed = make_idl_struct("Mixed", "CodecTest::Mixed", {"tag": byte, "value": float64})
    by_char = make_idl_union(
        "ByChar",
        "CodecUnions::ByChar",
        {"a": case["a", int32], "bc": case[["b", "c"], float64], "other": default[str]},
        discriminator=char,
    )
    m = T.Mixed(7, 2.5)
    made = H.cyclone().value(H.resolve(H.specification()["CodecTest::Mixed"]), m)
    assert m.serialize() == made.serialize() == mixed(7, 2.5).serialize()
    for ours, theirs in [
        (U.ByChar(a=3), by_char(a=3)),
        (U.ByChar("c", 1.5), by_char(discriminator="c", value=1.5)),
        (U.ByChar("z", "zz"), by_char(discriminator="z", value="zz")),
        (U.ByChar(other="o"), by_char(other="o")),
    ]:
        made = H.cyclone().value(H.resolve(H.specification()["CodecUnions::ByChar"]), ours)
        assert ours.serialize() == made.serialize() == theirs.serialize()


def test_bounded_strings_count_bytes_where_cyclone_counts_characters() -> None:
    """A documented difference: string<1> holds one UTF-8 byte for us, one character for
    Cyclone; what both accept encodes the same."""
    from miro_gen.exceptions import BAD_PARAM

    decl = H.specification()["CodecTest::Strings"]
    ty = H.resolve(decl)
    wide = T.Strings(one="\xe9")
    with pytest.raises(BAD_PARAM):
        wide.serialize()
    H.cyclone().value(ty, wide).serialize()  # Cyclone accepts it
    H.check_against_cyclone(decl, T.Strings(one="e", bounded="\xe9\xe9", name="\u20ac\u20ac"))


def test_chars_above_127_cyclone_cannot_write() -> None:
    """A documented difference: Cyclone packs char signed; we write ISO Latin-1 bytes."""
    decl = H.specification()["CodecTest::Primitives"]
    value = T.Primitives(c="\xe9")
    with pytest.raises(Exception):  # noqa: B017 - struct.error inside cyclonedds
        H.cyclone().value(H.resolve(decl), value).serialize()
    assert T.Primitives.deserialize(value.serialize()).c == "\xe9"
