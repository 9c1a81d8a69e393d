"""Questions the resolver asks of declarations and types while it resolves them: what a name
denotes through typedefs and forward declarations, whether a node is a type, which local
interface or incomplete forward declaration a type holds, and how to name values and types in
messages. Plain functions over miro_gen.idl.ast nodes, no resolver state."""

from __future__ import annotations

from typing import Any

from miro_gen.idl import ast
from miro_gen.idl.constants import FLOAT_TYPES, INT_RANGES


def unalias(t: Any) -> Any:
    """Follow named types and typedefs (without array dimensions) to the underlying type."""
    for _ in range(1000):
        if isinstance(t, ast.NamedType):
            if t.decl is None:
                return t
            t = t.decl
        if isinstance(t, ast.Forward) and t.full is not None:
            t = t.full
        if isinstance(t, ast.Typedef) and not t.dims:
            t = t.type
            continue
        if isinstance(t, ast.NamedType):
            continue
        return t
    return t  # pragma: no cover


def completed(node: Any) -> Any:
    """A forward declaration's full declaration once it has been seen; otherwise `node`."""
    if isinstance(node, ast.Forward) and node.full is not None:
        return node.full
    return node


def article(word: str) -> str:
    """`word` with its indefinite article: "an interface", "a struct"."""
    return f"{'an' if word[:1] in 'aeiou' else 'a'} {word}"


def all_bases(i: ast.Interface) -> list[ast.Interface]:
    """Every interface `i` inherits from, directly or not."""
    out: list[ast.Interface] = []
    todo = list(i.bases)
    while todo:
        b = todo.pop()
        if b not in out:
            out.append(b)
            todo.extend(b.bases)
    return out


def all_struct_members(s: ast.Struct) -> list[ast.Member]:
    out: list[ast.Member] = []
    seen: set[int] = set()
    while s is not None and id(s) not in seen:
        seen.add(id(s))
        out.extend(s.members)
        s = s.base  # type: ignore[assignment]
    return out


def is_type(node: Any) -> bool:
    if isinstance(node, ast.Forward):
        return True
    return isinstance(
        node,
        (
            ast.Typedef,
            ast.Struct,
            ast.Union_,
            ast.Enum,
            ast.Native,
            ast.Interface,
            ast.ValueType,
            ast.ValueBox,
        ),
    )


def local_type(t: Any, seen: set[int] | None = None) -> str | None:
    """The scoped name of the local interface that `t` is or holds (through typedefs,
    sequences, maps and members of structs, unions and exceptions), or None."""
    seen = set() if seen is None else seen
    if id(t) in seen:
        return None
    seen.add(id(t))
    if isinstance(t, ast.NamedType):
        return local_type(t.decl, seen) if t.decl is not None else None
    if isinstance(t, ast.Forward):
        if t.full is not None:
            return local_type(t.full, seen)
        return t.scoped_name if t.local else None
    if isinstance(t, ast.Interface):
        return t.scoped_name if t.local else None
    if isinstance(t, ast.Typedef):
        return local_type(t.type, seen)
    if isinstance(t, ast.SequenceType):
        return local_type(t.element, seen)
    if isinstance(t, ast.MapType):
        return local_type(t.key, seen) or local_type(t.value, seen)
    if isinstance(t, (ast.Struct, ast.Exception_)):
        members: list[Any] = t.members
    elif isinstance(t, ast.Union_):
        members = t.cases
    else:
        return None
    for m in members:
        if (local := local_type(m.type, seen)) is not None:
            return local
    return None


def incomplete_forward(t: Any, seen: set[int]) -> ast.Forward | None:
    if id(t) in seen:
        return None
    seen.add(id(t))
    if isinstance(t, ast.NamedType):
        return incomplete_forward(t.decl, seen) if t.decl is not None else None
    if isinstance(t, ast.Forward):
        return t if t.of in ("struct", "union") and t.full is None else None
    if isinstance(t, ast.SequenceType):
        return incomplete_forward(t.element, seen)
    if isinstance(t, ast.Typedef):
        return incomplete_forward(t.type, seen)
    return None


def kind_of_const(c: ast.Const, t: Any) -> str:
    if isinstance(t, ast.BaseType):
        n = t.name
        if n in INT_RANGES:
            return "int"
        if n in FLOAT_TYPES:
            return "float"
        return {"char": "char", "wchar": "wchar", "boolean": "bool"}.get(n, n)
    if isinstance(t, ast.StringType):
        return "wstring" if t.wide else "string"
    if isinstance(t, ast.FixedType):
        return "fixed"
    if isinstance(t, ast.Enum):
        return "enum"
    return "int"


def label_text(v: Any) -> str:
    if isinstance(v, ast.EnumValue):
        return v.scoped_name
    if isinstance(v, bool):
        return "TRUE" if v else "FALSE"
    if isinstance(v, str):
        return repr(v)
    return str(v)


def type_text(t: Any) -> str:
    if isinstance(t, ast.NamedType):
        return str(t.name)
    if isinstance(t, ast.SequenceType):
        return "a sequence"
    if isinstance(t, ast.MapType):
        return "a map"
    return str(t)
