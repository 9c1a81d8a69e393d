"""The shape of an IDL type as the Python back end sees it: typedefs followed, one kind each.

`shape_of` is the one place that turns a resolved IDL type into what the back end needs to
annotate, default and encode a value: a primitive with its `struct` code, a string, a sequence
of an element shape, an array with its dimensions, a named data type or an object reference.
Constructs the back end cannot generate are refused here, with their source position.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from miro_gen.diagnostics import SourcePos
from miro_gen.idl import ast


class Unsupported(Exception):
    """A construct the Python back end refuses, at a position."""

    def __init__(self, pos: SourcePos, message: str) -> None:
        super().__init__(message)
        self.pos = pos
        self.message = message


@dataclass(frozen=True)
class Prim:
    """A primitive IDL type: its `struct` code and size, its Python annotation and zero."""

    idl: str
    code: str  # struct format code
    size: int
    py: str  # annotation
    default: str  # default value expression
    array: str | None  # array module type code for bulk paths (None: no bulk path)
    to_wire: str = ""  # conversion applied when encoding ("ord" for char)
    from_wire: str = ""  # conversion applied when decoding ("chr" for char)

    @property
    def number(self) -> str | None:
        """The `array.array` type code of sequences and arrays of this primitive: the integer
        and floating-point types have one; boolean, char and octet keep their own mapping."""
        return self.array if self.idl != "octet" else None


PRIMS: dict[str, Prim] = {
    p.idl: p
    for p in (
        Prim("short", "h", 2, "int", "0", "h"),
        Prim("unsigned short", "H", 2, "int", "0", "H"),
        Prim("long", "i", 4, "int", "0", "i"),
        Prim("unsigned long", "I", 4, "int", "0", "I"),
        Prim("long long", "q", 8, "int", "0", "q"),
        Prim("unsigned long long", "Q", 8, "int", "0", "Q"),
        Prim("int8", "b", 1, "int", "0", "b"),
        Prim("uint8", "B", 1, "int", "0", "B"),
        Prim("octet", "B", 1, "int", "0", "B"),
        Prim("float", "f", 4, "float", "0.0", "f"),
        Prim("double", "d", 8, "float", "0.0", "d"),
        Prim("boolean", "?", 1, "bool", "False", None),
        Prim("char", "B", 1, "str", '"\\x00"', None, "ord", "chr"),
    )
}
ENUM_PRIM = Prim("enum", "I", 4, "int", "0", "I")
UNSUPPORTED_BASE = {
    "any": "the 'any' type",
    "ValueBase": "ValueBase",
    "wchar": "wchar",
    "long double": "long double",
}
# Shape kinds whose values are instances of a generated data class.
DATA_KINDS = ("struct", "union", "exception")
# Arrays of numbers with more elements than this are copied in bulk rather than packed with
# the fixed-size values around them (each packed element is a Python object on the way).
PACKED_NUMBERS_MAX = 16


@dataclass
class Shape:
    """A type as the codec sees it (typedefs followed); `alias` is the typedef it came from.

    kind: prim, enum, string, wstring, octets (`sequence<octet>`), seq, array, struct, union,
    exception or object; `prim` for prim, `decl` for enum, the data kinds and object, `elem` for
    seq and array, `bound` for string, wstring, octets and seq, `dims` for array.
    """

    kind: str
    prim: Prim | None = None
    decl: ast.Decl | None = None
    bound: int | None = None
    elem: Shape | None = None
    dims: tuple[int, ...] = ()
    alias: ast.Typedef | None = None

    @property
    def fixed(self) -> bool:
        """Whether values have a fixed size and layout, and are packed with one Struct (long
        arrays of numbers are fixed-size too, but are copied in bulk)."""
        if self.kind in ("prim", "enum"):
            return True
        if self.kind != "array" or self.elem is None or self.elem.kind not in ("prim", "enum"):
            return False
        return (
            self.elem.prim is None
            or not self.elem.prim.number
            or (self.count <= PACKED_NUMBERS_MAX)
        )

    @property
    def numbers(self) -> Prim | None:
        """The primitive of a value that is an `array.array`: a sequence of numbers, or the last
        dimension of an array of numbers (`long a[2][3]` is a list of two arrays of three)."""
        if self.kind == "seq" or (self.kind == "array" and len(self.dims) == 1):
            elem = self.elem
            if elem is not None and elem.kind == "prim" and elem.prim and elem.prim.number:
                return elem.prim
        return None

    @property
    def unit(self) -> Prim:
        """The primitive of a fixed shape (its elements', for arrays)."""
        s = self.elem if self.kind == "array" and self.elem is not None else self
        if s.kind == "enum":
            return ENUM_PRIM
        assert s.prim is not None, s
        return s.prim

    @property
    def count(self) -> int:
        """The number of elements of an array (all dimensions)."""
        n = 1
        for d in self.dims:
            n *= d
        return n

    @property
    def packed_format(self) -> str:
        """The struct format of one packed value ("h", "3i")."""
        n = self.count if self.kind == "array" else 1
        return f"{n}{self.unit.code}" if n > 1 else self.unit.code

    @property
    def row(self) -> Shape:
        """The element of an array's first dimension (a smaller array, or the element)."""
        assert self.elem is not None
        if len(self.dims) > 1:
            return Shape("array", elem=self.elem, dims=self.dims[1:])
        return self.elem

    @property
    def innermost(self) -> Shape:
        """The element type under all sequences and arrays."""
        s = self
        while s.kind in ("seq", "array") and s.elem is not None:
            s = s.elem
        return s

    @property
    def enum(self) -> ast.Enum:
        assert isinstance(self.decl, ast.Enum), self
        return self.decl

    @property
    def min_size(self) -> int:
        """The fewest bytes a value can take (to cap claimed sequence lengths)."""
        if self.fixed:
            return self.unit.size * (self.count if self.kind == "array" else 1)
        if self.kind in ("string", "wstring", "octets", "seq"):
            return 4
        if self.kind == "object":
            return 12
        if self.kind == "array" and self.elem is not None:
            return self.count * self.elem.min_size
        if isinstance(self.decl, ast.Struct | ast.Exception_):
            return sum(member_shape(m).min_size for m in self.decl.all_members)
        return 1


@cache  # asked for fields, codecs, bulk paths and size bounds alike; emptied after each build
def member_shape(m: ast.Member | ast.CaseBranch) -> Shape:
    """The shape of a struct member or union branch, with its declarator's dimensions (shared:
    never change it). `generate.build_modules` empties the cache when it is done."""
    return shape_of(m.type, m.pos, m.dims)


def shape_of(
    t: ast.TypeSpec | ast.Decl, pos: SourcePos, dims: list[int] | tuple[int, ...] = ()
) -> Shape:
    """The shape of IDL type `t` (with array `dims` when a declarator has them)."""
    if dims:
        return Shape("array", elem=shape_of(t, pos), dims=tuple(dims))
    match t:
        case ast.BaseType():
            if t.name in PRIMS:
                return Shape("prim", prim=PRIMS[t.name])
            if t.name == "Object":
                return Shape("object")
            what = UNSUPPORTED_BASE.get(t.name, t.name)
            raise Unsupported(pos, f"{what} is not supported by the CDR codec")
        case ast.StringType():
            return Shape("wstring" if t.wide else "string", bound=t.bound)
        case ast.SequenceType():
            elem = shape_of(t.element, pos)
            if elem.kind == "prim" and elem.prim is not None and elem.prim.idl == "octet":
                return Shape("octets", bound=t.bound)
            return Shape("seq", elem=elem, bound=t.bound)
        case ast.FixedType():
            raise Unsupported(pos, "fixed-point types are not supported by the CDR codec")
        case ast.MapType():
            raise Unsupported(pos, "map types are not supported by the CDR codec")
        case ast.NamedType():
            assert t.decl is not None, "unresolved name"
            return _named_shape(t.decl.resolved, pos)
        case ast.Decl():
            return _named_shape(t.resolved, pos)
    raise Unsupported(pos, f"unsupported type {t!r}")  # pragma: no cover


def _named_shape(decl: ast.Decl, pos: SourcePos) -> Shape:
    match decl:
        case ast.Typedef():
            inner = shape_of(decl.type, pos, decl.dims)
            inner.alias = decl
            return inner
        case ast.Enum():
            return Shape("enum", decl=decl)
        case ast.Struct():
            return Shape("struct", decl=decl)
        case ast.Union_():
            return Shape("union", decl=decl)
        case ast.Exception_():
            return Shape("exception", decl=decl)
        case ast.Forward() if not decl.is_interface:
            return Shape(decl.of, decl=decl)  # an incomplete struct/union inside a sequence
        case _ if decl.is_interface:
            return Shape("object", decl=decl)
    what = {ast.Native: "native types", ast.ValueType: "value types", ast.ValueBox: "value boxes"}
    raise Unsupported(
        pos, f"{what.get(type(decl), type(decl).__name__)} are not supported by the CDR codec"
    )
