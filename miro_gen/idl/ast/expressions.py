"""Names, constant expressions and annotations: the leaves of the IDL syntax tree
(`Node` is the base of every node)."""

from __future__ import annotations

from decimal import Decimal
from typing import TYPE_CHECKING, Union

from miro_gen.diagnostics import SourcePos

if TYPE_CHECKING:
    from miro_gen.idl.ast.declarations import Enum


class Node:
    """Base of all nodes: a readable `repr` from the slots."""

    __slots__ = ()

    def __repr__(self) -> str:
        names = [n for cls in reversed(type(self).__mro__) for n in getattr(cls, "__slots__", ())]
        inner = ", ".join(f"{n}={getattr(self, n)!r}" for n in names if n not in ("enum", "full"))
        return f"{type(self).__name__}({inner})"


class ScopedName(Node):
    """A name as written: `A::B` (relative) or `::A::B` (absolute)."""

    __slots__ = ("absolute", "parts", "pos")

    def __init__(self, parts: tuple[str, ...], absolute: bool, pos: SourcePos) -> None:
        self.parts = parts
        self.absolute = absolute
        self.pos = pos

    def __str__(self) -> str:
        return ("::" if self.absolute else "") + "::".join(self.parts)


ConstValue = Union[int, float, str, bool, Decimal, "EnumValue"]


class EnumValue(Node):
    """The value of an enumerator: its enum, its name and its ordinal (hashable, immutable)."""

    __slots__ = ("enum", "name", "ordinal")

    def __init__(self, enum: Enum, name: str, ordinal: int) -> None:
        self.enum = enum
        self.name = name
        self.ordinal = ordinal

    @property
    def scoped_name(self) -> str:
        # Enumerators belong to the scope enclosing their enum (CORBA 3.0 section 3.11.2.4).
        return "::".join((*self.enum.scope_path[:-1], self.name))

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, EnumValue)
            and other.enum is self.enum
            and other.ordinal == self.ordinal
        )

    def __hash__(self) -> int:
        return hash((id(self.enum), self.ordinal))


class Literal(Node):
    """A literal; `kind` is int, float, fixed, char, wchar, string, wstring or bool."""

    __slots__ = ("kind", "pos", "value")

    def __init__(self, kind: str, value: ConstValue, pos: SourcePos) -> None:
        self.kind = kind
        self.value = value
        self.pos = pos


class NameRef(Node):
    """A constant or enumerator used in an expression."""

    __slots__ = ("name", "pos")

    def __init__(self, name: ScopedName, pos: SourcePos) -> None:
        self.name = name
        self.pos = pos


class UnaryOp(Node):
    """`-x`, `+x` or `~x`."""

    __slots__ = ("op", "operand", "pos")

    def __init__(self, op: str, operand: Expr, pos: SourcePos) -> None:
        self.op = op
        self.operand = operand
        self.pos = pos


class BinaryOp(Node):
    """`a OP b` with OP one of `| ^ & >> << + - * / %`."""

    __slots__ = ("left", "op", "pos", "right")

    def __init__(self, op: str, left: Expr, right: Expr, pos: SourcePos) -> None:
        self.op = op
        self.left = left
        self.right = right
        self.pos = pos


Expr = Literal | NameRef | UnaryOp | BinaryOp


class Annotation(Node):
    """`@name` or `@name(args)`; one unnamed argument is stored under "value"."""

    __slots__ = ("args", "name", "params", "pos")

    def __init__(
        self,
        name: ScopedName,
        args: dict[str, Expr],
        pos: SourcePos,
        params: dict[str, ConstValue] | None = None,
    ) -> None:
        self.name = name
        self.args = args
        self.pos = pos
        self.params: dict[str, ConstValue] = params if params is not None else {}  # evaluated

    @property
    def short_name(self) -> str:
        return self.name.parts[-1]
