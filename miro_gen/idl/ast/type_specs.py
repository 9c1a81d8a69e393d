"""Type specs: base types, strings, sequences, fixed-point, maps, and names of declared types."""

from __future__ import annotations

from typing import TYPE_CHECKING, Union

from miro_gen.diagnostics import SourcePos
from miro_gen.idl.ast.expressions import Expr, Node, ScopedName

if TYPE_CHECKING:
    from miro_gen.idl.ast.declarations import Decl, Enum, Struct, Union_


class BaseType(Node):
    """A basic type, named by its IDL spelling (`long`, `unsigned long long`, `boolean`...)."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __str__(self) -> str:
        return self.name

    def __eq__(self, other: object) -> bool:
        return isinstance(other, BaseType) and other.name == self.name

    def __hash__(self) -> int:
        return hash(self.name)


class StringType(Node):
    """`string`, `wstring`, `string<N>`, `wstring<N>`."""

    __slots__ = ("bound", "bound_expr", "pos", "wide")

    def __init__(
        self, wide: bool, bound_expr: Expr | None, pos: SourcePos, bound: int | None = None
    ) -> None:
        self.wide = wide
        self.bound_expr = bound_expr
        self.pos = pos
        self.bound = bound

    def __str__(self) -> str:
        base = "wstring" if self.wide else "string"
        return f"{base}<{self.bound}>" if self.bound is not None else base


class SequenceType(Node):
    """`sequence<T>` or `sequence<T, N>`."""

    __slots__ = ("bound", "bound_expr", "element", "pos")

    def __init__(
        self, element: TypeSpec, bound_expr: Expr | None, pos: SourcePos, bound: int | None = None
    ) -> None:
        self.element = element
        self.bound_expr = bound_expr
        self.pos = pos
        self.bound = bound


class FixedType(Node):
    """`fixed<D, S>`, or the bare `fixed` of a constant declaration (no digits or scale)."""

    __slots__ = ("digits", "digits_expr", "pos", "scale", "scale_expr")

    def __init__(
        self,
        digits_expr: Expr | None,
        scale_expr: Expr | None,
        pos: SourcePos,
        digits: int | None = None,
        scale: int | None = None,
    ) -> None:
        self.digits_expr = digits_expr
        self.scale_expr = scale_expr
        self.pos = pos
        self.digits = digits
        self.scale = scale


class MapType(Node):
    """IDL 4 `map<K, V>` or `map<K, V, N>`."""

    __slots__ = ("bound", "bound_expr", "key", "pos", "value")

    def __init__(
        self,
        key: TypeSpec,
        value: TypeSpec,
        bound_expr: Expr | None,
        pos: SourcePos,
        bound: int | None = None,
    ) -> None:
        self.key = key
        self.value = value
        self.bound_expr = bound_expr
        self.pos = pos
        self.bound = bound


class NamedType(Node):
    """A reference to a declared type by name; `decl` is set by the resolver."""

    __slots__ = ("decl", "name")

    def __init__(self, name: ScopedName, decl: Decl | None = None) -> None:
        self.name = name
        self.decl = decl


TypeSpec = Union[
    BaseType, StringType, SequenceType, FixedType, MapType, NamedType, "Struct", "Union_", "Enum"
]
