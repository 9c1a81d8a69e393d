"""CORBA TypeCodes: what an `any` says about the value it carries, read and written in CDR.

A TypeCode is a kind (`TCKind`) and, for most kinds, parameters: the repository id and name of
named types, members, union cases, enumerators, bounds, element types. Simple kinds carry
nothing; strings carry a bound; the rest carry their parameters in an encapsulation. A type that
contains itself (through a sequence) refers back with an indirection: kind 0xFFFFFFFF and the
(negative) distance to the TypeCode it repeats, which may lie outside the current encapsulation.
Reading keeps every TypeCode's absolute offset so that any indirection resolves; writing emits
one for each TypeCode already being written.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

from miro_gen.exceptions import BAD_PARAM, MARSHAL
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput, encapsulation_input

INDIRECTION = 0xFFFFFFFF
_MAX_DEPTH = 100  # TypeCodes nested deeper than this are refused (hostile input)


class TCKind(enum.IntEnum):
    tk_null = 0
    tk_void = 1
    tk_short = 2
    tk_long = 3
    tk_ushort = 4
    tk_ulong = 5
    tk_float = 6
    tk_double = 7
    tk_boolean = 8
    tk_char = 9
    tk_octet = 10
    tk_any = 11
    tk_TypeCode = 12
    tk_Principal = 13
    tk_objref = 14
    tk_struct = 15
    tk_union = 16
    tk_enum = 17
    tk_string = 18
    tk_sequence = 19
    tk_array = 20
    tk_alias = 21
    tk_except = 22
    tk_longlong = 23
    tk_ulonglong = 24
    tk_longdouble = 25
    tk_wchar = 26
    tk_wstring = 27
    tk_fixed = 28
    tk_value = 29
    tk_value_box = 30
    tk_native = 31
    tk_abstract_interface = 32
    tk_local_interface = 33


K = TCKind
# Kinds whose parameters are an encapsulation, and those without parameters.
_COMPLEX = {
    K.tk_objref, K.tk_struct, K.tk_union, K.tk_enum, K.tk_sequence, K.tk_array, K.tk_alias,
    K.tk_except, K.tk_value, K.tk_value_box, K.tk_native, K.tk_abstract_interface,
    K.tk_local_interface,
}  # fmt: skip
_NAMED = {
    K.tk_objref, K.tk_struct, K.tk_union, K.tk_enum, K.tk_alias, K.tk_except, K.tk_value,
    K.tk_value_box, K.tk_native, K.tk_abstract_interface, K.tk_local_interface,
}  # fmt: skip
# (size, struct format) of the primitive kinds.
PRIMITIVES: dict[int, tuple[int, str]] = {
    K.tk_short: (2, "h"),
    K.tk_long: (4, "i"),
    K.tk_ushort: (2, "H"),
    K.tk_ulong: (4, "I"),
    K.tk_float: (4, "f"),
    K.tk_double: (8, "d"),
    K.tk_boolean: (1, "B"),
    K.tk_char: (1, "B"),
    K.tk_octet: (1, "B"),
    K.tk_longlong: (8, "q"),
    K.tk_ulonglong: (8, "Q"),
}


@dataclass(eq=False)
class TypeCode:
    """One TypeCode. Which fields mean something depends on `kind` (see the module doc)."""

    kind: TCKind
    id: str = ""
    name: str = ""
    members: list[tuple[str, TypeCode]] = field(default_factory=list)  # struct, except
    discriminator: TypeCode | None = None  # union
    default_index: int = -1  # union: the index of the default case, or -1
    cases: list[tuple[Any, str, TypeCode]] = field(default_factory=list)  # union: label, name
    enumerators: list[str] = field(default_factory=list)
    length: int = 0  # bound of strings and sequences (0: none), length of arrays
    content: TypeCode | None = None  # sequence, array, alias, value box
    digits: int = 0  # fixed
    scale: int = 0

    def resolved(self) -> TypeCode:
        """This TypeCode with aliases followed."""
        tc = self
        while tc.kind == K.tk_alias and tc.content is not None:
            tc = tc.content
        return tc

    def equivalent(self, other: TypeCode) -> bool:
        """Whether the two describe the same type: by repository id when both have one,
        else structurally, aliases followed."""
        return _equivalent(self, other, set())

    def __repr__(self) -> str:
        if self.kind in _NAMED:
            return f"TypeCode({self.kind.name}, {self.id!r})"
        if self.content is not None:
            return f"TypeCode({self.kind.name}, {self.content!r}, {self.length})"
        return f"TypeCode({self.kind.name})"


def _equivalent(a: TypeCode, b: TypeCode, seen: set[tuple[int, int]]) -> bool:
    a, b = a.resolved(), b.resolved()
    if a is b or (id(a), id(b)) in seen:
        return True
    if a.kind != b.kind:
        return False
    if a.kind in _NAMED and a.id and b.id:
        return a.id == b.id
    seen.add((id(a), id(b)))
    if a.kind in (K.tk_struct, K.tk_except):
        return len(a.members) == len(b.members) and all(
            _equivalent(x[1], y[1], seen) for x, y in zip(a.members, b.members, strict=True)
        )
    if a.kind == K.tk_union:
        assert a.discriminator is not None and b.discriminator is not None
        return (
            len(a.cases) == len(b.cases)
            and _equivalent(a.discriminator, b.discriminator, seen)
            and all(_equivalent(x[2], y[2], seen) for x, y in zip(a.cases, b.cases, strict=True))
        )
    if a.kind == K.tk_enum:
        return a.enumerators == b.enumerators
    if a.kind in (K.tk_sequence, K.tk_array):
        assert a.content is not None and b.content is not None
        return a.length == b.length and _equivalent(a.content, b.content, seen)
    if a.kind in (K.tk_string, K.tk_wstring):
        return a.length == b.length
    return True


_SIMPLE: dict[TCKind, TypeCode] = {
    k: TypeCode(k) for k in TCKind if k not in _COMPLEX and k not in (K.tk_string,)
}


def simple(kind: TCKind) -> TypeCode:
    """The shared TypeCode of a kind without parameters."""
    return _SIMPLE[kind]


def string_tc(bound: int = 0, wide: bool = False) -> TypeCode:
    return TypeCode(K.tk_wstring if wide else K.tk_string, length=bound)


def objref_tc(repo_id: str, name: str = "") -> TypeCode:
    return TypeCode(K.tk_objref, repo_id, name or repo_id.rpartition("/")[2].partition(":")[0])


# ---- writing ----------------------------------------------------------------------------------


def write_typecode(out: CdrOutput, tc: TypeCode) -> None:
    """`tc` in CDR at the end of `out` (whose alignment counts from its offset 0)."""
    _write(out, tc, 0, {})


def _write(out: CdrOutput, tc: TypeCode, base: int, open_: dict[int, int]) -> None:
    """`base`: the absolute offset of `out`'s offset 0; `open_`: absolute offsets of the
    TypeCodes being written around this one (for indirections)."""
    out.align(4)
    here = base + len(out.buf)
    if id(tc) in open_:
        out.ulong(INDIRECTION)
        out.long(open_[id(tc)] - (here + 4))
        return
    out.ulong(tc.kind)
    k = tc.kind
    if k in (K.tk_string, K.tk_wstring):
        out.ulong(tc.length)
        return
    if k == K.tk_fixed:
        out.ushort(tc.digits)
        out.short(tc.scale)
        return
    if k not in _COMPLEX:
        return
    open_[id(tc)] = here
    out.ulong(0)  # the encapsulation's length, filled in below
    start = len(out.buf)
    inner = CdrOutput(bytearray(b"\x01"))
    inner_base = base + start
    if k in _NAMED:
        inner.string(tc.id)
        inner.string(tc.name)
    if k in (K.tk_struct, K.tk_except):
        inner.ulong(len(tc.members))
        for name, member in tc.members:
            inner.string(name)
            _write(inner, member, inner_base, open_)
    elif k == K.tk_union:
        assert tc.discriminator is not None
        _write(inner, tc.discriminator, inner_base, open_)
        inner.long(tc.default_index)
        inner.ulong(len(tc.cases))
        for label, name, case in tc.cases:
            write_label(inner, tc.discriminator, label)
            inner.string(name)
            _write(inner, case, inner_base, open_)
    elif k == K.tk_enum:
        inner.ulong(len(tc.enumerators))
        for e in tc.enumerators:
            inner.string(e)
    elif k in (K.tk_sequence, K.tk_array):
        assert tc.content is not None
        _write(inner, tc.content, inner_base, open_)
        inner.ulong(tc.length)
    elif k in (K.tk_alias, K.tk_value_box):
        assert tc.content is not None
        _write(inner, tc.content, inner_base, open_)
    elif k == K.tk_value:
        raise BAD_PARAM("value type TypeCodes are not supported")
    del open_[id(tc)]
    out.raw(inner.buf)
    out.buf[start - 4 : start] = len(inner.buf).to_bytes(4, "little")


def write_label(out: CdrOutput, disc: TypeCode, value: Any) -> None:
    d = disc.resolved().kind
    if d == K.tk_enum:
        out.ulong(int(value))
    elif d == K.tk_boolean:
        out.boolean(bool(value))
    elif d == K.tk_char:
        out.octet(ord(value) if isinstance(value, str) else int(value))
    elif d in (K.tk_short, K.tk_ushort):
        (out.short if d == K.tk_short else out.ushort)(int(value))
    elif d in (K.tk_long, K.tk_ulong):
        (out.long if d == K.tk_long else out.ulong)(int(value))
    elif d in (K.tk_longlong, K.tk_ulonglong):
        (out.longlong if d == K.tk_longlong else out.ulonglong)(int(value))
    elif d == K.tk_octet:
        out.octet(int(value))
    else:
        raise BAD_PARAM(f"a union discriminator of kind {d.name}")


def read_label(inp: CdrInput, disc: TypeCode) -> Any:
    d = disc.resolved().kind
    readers = {
        K.tk_enum: inp.ulong, K.tk_boolean: inp.boolean, K.tk_char: inp.char,
        K.tk_short: inp.short, K.tk_ushort: inp.ushort, K.tk_long: inp.long,
        K.tk_ulong: inp.ulong, K.tk_longlong: inp.longlong, K.tk_ulonglong: inp.ulonglong,
        K.tk_octet: inp.octet, K.tk_wchar: inp.ushort,
    }  # fmt: skip
    reader = readers.get(d)
    if reader is None:
        raise MARSHAL(f"a union discriminator of kind {d.name}")
    return reader()


# ---- reading ----------------------------------------------------------------------------------


def read_typecode(inp: CdrInput) -> TypeCode:
    """The TypeCode at `inp`'s position (alignment and indirections relative to its data)."""
    return _read(inp, 0, {}, 0)


def _read(inp: CdrInput, base: int, seen: dict[int, TypeCode], depth: int) -> TypeCode:
    if depth > _MAX_DEPTH:
        raise MARSHAL("TypeCode nested too deeply")
    inp.align(4)
    here = base + inp.pos
    kind = inp.ulong()
    if kind == INDIRECTION:
        offset = inp.long()
        target = seen.get(here + 4 + offset)
        if target is None or offset >= -4:
            raise MARSHAL(f"TypeCode indirection {offset} points at no TypeCode")
        return target
    try:
        k = TCKind(kind)
    except ValueError:
        raise MARSHAL(f"unknown TypeCode kind {kind}") from None
    if k in (K.tk_string, K.tk_wstring):
        tc = TypeCode(k, length=inp.ulong())
        seen[here] = tc
        return tc
    if k == K.tk_fixed:
        tc = TypeCode(k, digits=inp.ushort(), scale=inp.short())
        seen[here] = tc
        return tc
    if k not in _COMPLEX:
        seen[here] = _SIMPLE[k]
        return _SIMPLE[k]
    tc = TypeCode(k)
    seen[here] = tc
    n = inp.length(1, "TypeCode parameters")
    start = inp.pos
    enc = encapsulation_input(inp.raw(n), "TypeCode parameters")
    inner_base = base + start
    if k in _NAMED:
        tc.id = enc.string("repository id")
        tc.name = enc.string("type name")
    if k in (K.tk_struct, K.tk_except):
        for _ in range(enc.length(8, "members")):
            name = enc.string("member name")
            tc.members.append((name, _read(enc, inner_base, seen, depth + 1)))
    elif k == K.tk_union:
        tc.discriminator = _read(enc, inner_base, seen, depth + 1)
        tc.default_index = enc.long()
        for _ in range(enc.length(9, "union cases")):
            label = read_label(enc, tc.discriminator)
            name = enc.string("case name")
            tc.cases.append((label, name, _read(enc, inner_base, seen, depth + 1)))
    elif k == K.tk_enum:
        tc.enumerators = [enc.string("enumerator") for _ in range(enc.length(4, "enumerators"))]
    elif k in (K.tk_sequence, K.tk_array):
        tc.content = _read(enc, inner_base, seen, depth + 1)
        tc.length = enc.ulong()
    elif k in (K.tk_alias, K.tk_value_box):
        tc.content = _read(enc, inner_base, seen, depth + 1)
    elif k == K.tk_value:
        raise MARSHAL("value type TypeCodes are not supported")
    return tc


def max_alignment(tc: TypeCode, seen: set[int] | None = None) -> int:
    """The largest alignment a value of `tc` may need (1, 2, 4 or 8)."""
    seen = set() if seen is None else seen
    tc = tc.resolved()
    if id(tc) in seen:
        return 1
    k = tc.kind
    if k in PRIMITIVES:
        return PRIMITIVES[k][0]
    if k in (K.tk_any, K.tk_longdouble):
        return 8
    if k in (K.tk_sequence, K.tk_array):
        assert tc.content is not None
        seen.add(id(tc))
        return max(4 if k == K.tk_sequence else 1, max_alignment(tc.content, seen))
    if k in (K.tk_struct, K.tk_except):
        seen.add(id(tc))
        return max([1, *(max_alignment(m, seen) for _, m in tc.members)])
    if k == K.tk_union:
        seen.add(id(tc))
        assert tc.discriminator is not None
        parts = [
            max_alignment(tc.discriminator, seen),
            *(max_alignment(c, seen) for *_, c in tc.cases),
        ]
        return max(parts)
    return 4
