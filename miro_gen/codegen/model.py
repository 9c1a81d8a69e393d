"""The Python back end's context model: what the templates in templates/idl/ render.

For each IDL file and each IDL module it declares things in, a `PyModule` lists the generated
items in dependency order, with every name, annotation, default value and import computed here,
and each codec as a list of small steps (`Step`): runs of fixed-size values packed with one
precompiled `struct.Struct`, bulk paths for sequences of primitives and of flat structs, loops
for the rest. Templates only lay the steps out as code.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from decimal import Decimal
from typing import Any

from miro_gen.codegen import names
from miro_gen.codegen.schema import data_schema
from miro_gen.diagnostics import SourcePos
from miro_gen.idl import ast


class Unsupported(Exception):
    """A construct the Python back end refuses, at a position."""

    def __init__(self, pos: SourcePos, message: str) -> None:
        super().__init__(message)
        self.pos = pos
        self.message = message


# ---- primitive types ------------------------------------------------------------------------


@dataclass(frozen=True)
class Prim:
    idl: str
    code: str  # struct format code
    size: int
    py: str  # annotation
    default: str  # default value expression
    array: str | None  # array module type code for bulk paths (None: no bulk path)
    to_wire: str = ""  # conversion applied when encoding ("ord" for char)
    from_wire: str = ""  # conversion applied when decoding ("chr" for char)


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


@dataclass
class Shape:
    """A type as the codec sees it (typedefs followed); `alias` is the typedef it came from."""

    kind: str  # prim, enum, string, octets, seq, array, struct, union, exception, object
    prim: Prim | None = None
    decl: Any = None
    bound: int | None = None
    elem: Shape | None = None
    dims: tuple[int, ...] = ()
    alias: Any = None

    @property
    def fixed(self) -> bool:
        """Whether values have a fixed size and layout (packable with one Struct)."""
        if self.kind in ("prim", "enum"):
            return True
        return self.kind == "array" and self.elem is not None and self.elem.kind in ("prim", "enum")

    @property
    def unit(self) -> Prim:
        """The primitive of a fixed shape (its elements', for arrays)."""
        s = self.elem if self.kind == "array" and self.elem is not None else self
        return ENUM_PRIM if s.kind == "enum" else s.prim  # type: ignore[return-value]

    @property
    def count(self) -> int:
        n = 1
        for d in self.dims:
            n *= d
        return n


def completed(node: Any) -> Any:
    if isinstance(node, ast.Forward) and node.full is not None:
        return node.full
    return node


def shape_of(t: Any, pos: SourcePos, dims: list[int] | tuple[int, ...] = ()) -> Shape:
    """The shape of IDL type `t` (with array `dims` when a declarator has them)."""
    if dims:
        return Shape("array", elem=shape_of(t, pos), dims=tuple(dims))
    if isinstance(t, ast.BaseType):
        if t.name in PRIMS:
            return Shape("prim", prim=PRIMS[t.name])
        if t.name == "Object":
            return Shape("object")
        raise Unsupported(
            pos, f"{UNSUPPORTED_BASE.get(t.name, t.name)} is not supported by the CDR codec"
        )
    if isinstance(t, ast.StringType):
        if t.wide:
            raise Unsupported(pos, "wstring is not supported by the CDR codec")
        return Shape("string", bound=t.bound)
    if isinstance(t, ast.SequenceType):
        elem = shape_of(t.element, pos)
        if elem.kind == "prim" and elem.prim is not None and elem.prim.idl == "octet":
            return Shape("octets", bound=t.bound)
        return Shape("seq", elem=elem, bound=t.bound)
    if isinstance(t, ast.FixedType):
        raise Unsupported(pos, "fixed-point types are not supported by the CDR codec")
    if isinstance(t, ast.MapType):
        raise Unsupported(pos, "map types are not supported by the CDR codec")
    if isinstance(t, ast.NamedType):
        return _named_shape(completed(t.decl), pos)
    if isinstance(t, ast.Decl):
        return _named_shape(completed(t), pos)
    raise Unsupported(pos, f"unsupported type {t!r}")  # pragma: no cover


def _named_shape(decl: Any, pos: SourcePos) -> Shape:
    if isinstance(decl, ast.Typedef):
        inner = shape_of(decl.type, pos, decl.dims)
        inner.alias = decl
        return inner
    if isinstance(decl, ast.Enum):
        return Shape("enum", decl=decl)
    if isinstance(decl, ast.Struct):
        return Shape("struct", decl=decl)
    if isinstance(decl, ast.Union_):
        return Shape("union", decl=decl)
    if isinstance(decl, ast.Exception_):
        return Shape("exception", decl=decl)
    if isinstance(decl, ast.Interface) or (
        isinstance(decl, ast.Forward) and decl.of == "interface"
    ):
        return Shape("object", decl=decl)
    if isinstance(decl, ast.Forward):
        return Shape(decl.of, decl=decl)  # an incomplete struct/union inside a sequence
    what = {ast.Native: "native types", ast.ValueType: "value types", ast.ValueBox: "value boxes"}
    raise Unsupported(
        pos, f"{what.get(type(decl), type(decl).__name__)} are not supported by the CDR codec"
    )


def min_size(shape: Shape) -> int:
    """The fewest bytes a value of `shape` can take (to cap claimed sequence lengths)."""
    if shape.fixed:
        return shape.unit.size * (shape.count if shape.kind == "array" else 1)
    if shape.kind in ("string", "octets", "seq"):
        return 4
    if shape.kind == "object":
        return 12
    if shape.kind == "array" and shape.elem is not None:
        return shape.count * min_size(shape.elem)
    if shape.kind in ("struct", "exception") and isinstance(
        shape.decl, (ast.Struct, ast.Exception_)
    ):
        return sum(min_size(shape_of(m.type, m.pos, m.dims)) for m in all_members(shape.decl))
    return 1


def all_members(decl: ast.Struct | ast.Exception_) -> list[ast.Member]:
    """A struct's members, those of its IDL 4 base struct first."""
    chain: list[Any] = []
    node: Any = decl
    while node is not None:
        chain.append(node)
        node = getattr(node, "base", None)
    return [m for s in reversed(chain) for m in s.members]


# ---- codec steps ---------------------------------------------------------------------------


@dataclass
class Step:
    """One step of an encoder or decoder; `kind` selects its template."""

    kind: str
    expr: str = ""  # the value encoded, or the variable a decoded value goes to
    what: str = ""  # for error messages: Miro::Struct.member
    align: int = 1
    codec: str = ""  # module-level Struct pair / pack function / codec function
    size: int = 0
    items: list[str] = field(default_factory=list)  # packed expressions / unpacked assignments
    bound: int | None = None
    code: str = ""  # array type code
    count: int = 0
    var: str = ""  # loop variable
    body: list[Step] = field(default_factory=list)
    labels: list[tuple[str, list[Step]]] = field(default_factory=list)  # union branches
    annotation: str = ""  # declared type of an assigned variable
    # packed values, for naming the one that does not fit: (what, struct format, expression)
    checks: list[tuple[str, str, str]] = field(default_factory=list)

    @property
    def bound_expr(self) -> str:
        return "None" if self.bound is None else str(self.bound)


@dataclass
class Field:
    name: str
    annotation: str
    default: str  # "= value" or "= _dc.field(default_factory=...)"
    doc: str | None


@dataclass
class Item:
    """A generated declaration: kind is enum, struct, union, exception, typedef, const or stub."""

    kind: str
    name: str
    decl: Any
    doc: str | None = None
    repo_id: str = ""
    scoped_name: str = ""
    fields: list[Field] = field(default_factory=list)
    bases: list[str] = field(default_factory=list)
    value: str = ""  # typedef target, constant value
    annotation: str = ""
    enumerators: list[tuple[str, int, str | None]] = field(default_factory=list)
    encode: list[Step] = field(default_factory=list)
    decode: list[Step] = field(default_factory=list)
    decode_call: str = ""  # the class a decoder constructs
    decode_args: list[str] = field(default_factory=list)  # and its arguments
    schema: str = ""
    type_hash: str = ""
    nested: list[tuple[str, str]] = field(default_factory=list)  # class attribute aliases
    union: dict[str, Any] = field(default_factory=dict)
    operations: list[Operation] = field(default_factory=list)
    quoted: bool = False  # typedef of a type defined later (recursion): a string alias
    # An enum's enumerators are module constants only when the enum is declared in a module;
    # nested in an interface, struct or union they are attributes of that class (CORBA scoping).
    module_constants: bool = True


@dataclass
class Param:
    name: str  # Python name
    annotation: str
    mode: str


@dataclass
class Operation:
    name: str  # Python method name
    wire: str  # operation name on the wire
    doc: str | None
    oneway: bool
    params: list[Param]
    returns: str  # annotation of what the Python method returns
    results: list[str]  # names of returned values, in order (result first)
    encode_in: list[Step]
    decode_in: list[Step]
    encode_out: list[Step]
    decode_out: list[Step]
    raises: list[str]  # exception classes
    what: str
    abstract: bool = True


@dataclass
class PyModule:
    """One generated module (`Miro/Example_idl.py` or `Miro__POA/Example_idl.py`)."""

    package: str
    stem: str
    source: str
    idl_module: str
    poa: bool = False
    items: list[Item] = field(default_factory=list)
    imports: dict[str, str] = field(default_factory=dict)  # module -> alias
    structs: dict[str, str] = field(default_factory=dict)  # format -> variable
    getters: dict[str, tuple[str, ...]] = field(default_factory=dict)  # variable -> attributes
    exports: list[str] = field(default_factory=list)
    uses: set[str] = field(default_factory=set)  # runtime modules used: dc, enum, abc, decimal, ...
    noqa: set[str] = field(default_factory=set)  # ruff rules the whole module is exempt from

    @property
    def name(self) -> str:
        return f"{self.package}.{self.stem}"

    @property
    def sorted_exports(self) -> list[str]:
        """`__all__` in the order ruff's RUF022 wants: constants, classes, then the rest."""
        return sorted(self.exports, key=isort_key)

    @property
    def import_blocks(self) -> list[list[str]]:
        """Non-standard imports in isort's sections for this layout: other generated top-level
        packages (third party), then this module's own package with miro_gen (first party);
        each sorted as isort sorts (case-insensitively)."""
        own = self.package.split(".")[0]
        runtime = {"exc": "miro_gen.exceptions", "cdr": "miro_gen.runtime.cdr"}
        runtime["rpc"] = "miro_gen.runtime.rpc"
        aliases = {"miro_gen.exceptions": "_exc", "miro_gen.runtime.cdr": "_cdr"}
        aliases["miro_gen.runtime.rpc"] = "_rpc"
        third = {m: a for m, a in self.imports.items() if m.split(".")[0] != own}
        first = {m: a for m, a in self.imports.items() if m.split(".")[0] == own}
        first.update({runtime[u]: aliases[runtime[u]] for u in self.uses if u in runtime})
        stdlib = {
            "abc": "import abc as _abc",
            "dc": "import dataclasses as _dc",
            "decimal": "import decimal as _decimal",
            "enum": "import enum as _enum",
            "operator": "import operator as _operator",
            "typing": "import typing as _t",
        }
        blocks = [[line for use, line in stdlib.items() if use in self.uses]]
        blocks = [b for b in blocks if b]
        for section in (third, first):
            if section:
                blocks.append(
                    [f"import {m} as {a}" for m, a in sorted(section.items(), key=_module_key)]
                )
        return blocks

    @property
    def path(self) -> str:
        return "/".join(self.package.split(".")) + f"/{self.stem}.py"


def _module_key(item: tuple[str, str]) -> list[Any]:
    return _natural(item[0].lower())


def _natural(text: str) -> list[Any]:
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", text)]


def isort_key(name: str) -> tuple[int, list[Any]]:
    if len(name) > 1 and name.isupper():
        kind = 0
    elif name[:1].isupper() or (name[:1] == "_" and name[1:2].isupper()):
        kind = 1
    else:
        kind = 2
    return kind, _natural(name)


def type_hash(schema: str) -> str:
    return hashlib.sha256(schema.encode("utf-8")).hexdigest()


def const_literal(value: Any) -> str:
    if isinstance(value, bool):
        return "True" if value else "False"
    if isinstance(value, Decimal):
        return f'_decimal.Decimal("{value}")'
    if isinstance(value, float):
        return repr(value)
    return repr(value)


__all__ = [
    "PRIMS",
    "Field",
    "Item",
    "Operation",
    "Param",
    "PyModule",
    "Shape",
    "Step",
    "Unsupported",
    "all_members",
    "completed",
    "const_literal",
    "data_schema",
    "min_size",
    "names",
    "shape_of",
    "type_hash",
]
