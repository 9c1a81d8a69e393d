"""Every data type of the code generator's test IDL (tests/codegen/types.idl: every type kind,
recursion, nested types, unions of every discriminator kind) travels inside a CORBA `any`: its
TypeCode is read from the type's data schema, written and read back, and random values land at
every offset of a GIOP stream (realigned), to come back equal."""

from __future__ import annotations

from typing import Any

import codegen_helpers as H
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from miro_gen.corba.anys import read_any, typecode_for, write_any
from miro_gen.corba.typecode import read_typecode, write_typecode
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

TYPES = H.data_types()
IDS = [d.scoped_name for d in TYPES]


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
def test_the_typecode_of_every_type(decl: Any) -> None:
    cls = H.pyclass(decl)
    tc = typecode_for(cls)
    assert tc.id == cls._repo_id
    out = CdrOutput(bytearray(5))
    write_typecode(out, tc)
    back = read_typecode(CdrInput(bytes(out.buf), 5))
    assert back.equivalent(tc) and tc.equivalent(back)


@pytest.mark.parametrize("decl", TYPES, ids=IDS)
@settings(H.SETTINGS, max_examples=8)
@given(data=st.data(), start=st.integers(0, 7))
def test_every_type_travels_in_an_any(decl: Any, data: st.DataObject, start: int) -> None:
    value = data.draw(H.values(H.resolve(decl)))
    out = CdrOutput(bytearray(start))
    write_any(out, value)
    out.octet(0x5A)
    inp = CdrInput(bytes(out.buf), start)
    back = read_any(inp)
    assert type(back) is type(value)
    assert H.plain(back) == H.plain(value)
    assert inp.octet() == 0x5A and inp.left() == 0
