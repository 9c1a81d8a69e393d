"""Identical redeclarations, which rosidl accepts, taken out before resolution.

rosidl's `.idl` files have no include guards and rosidl's parser never follows includes, so the
same typedef appears in several files of a package (`typedef double double__36[36];` in
`PoseWithCovariance.idl` and `TwistWithCovariance.idl`, both in `geometry_msgs::msg`), twice in
one file (a `.srv` whose request and response both have `boolean[3]` fields), and a type read
from its `.msg` may come again from an `.idl` that includes it. A declaration that repeats an
earlier one of the same scoped name exactly (positions and comments aside) is dropped here;
one that differs is left for the resolver to report as the clash it is.
"""

from __future__ import annotations

from typing import Any

from miro_gen.diagnostics import SourcePos
from miro_gen.idl import ast

# Where and how a declaration was written, and (once resolved) what its names stand for.
_IGNORED = frozenset(("pos", "doc", "instance", "pragmas", "decl", "full", "enum"))


def drop_identical(definitions: list[ast.Definition]) -> list[ast.Definition]:
    """`definitions` without the declarations that repeat an earlier one exactly."""
    return _walk(definitions, (), {})


def same_declaration(a: ast.Decl, b: ast.Decl) -> bool:
    """Whether two declarations say the same, positions and comments aside."""
    return bool(_signature(a) == _signature(b))


def _walk(
    definitions: list[ast.Definition], path: tuple[str, ...], seen: dict[tuple[str, ...], Any]
) -> list[ast.Definition]:
    out: list[ast.Definition] = []
    for d in definitions:
        if isinstance(d, ast.Module):
            d.definitions = _walk(d.definitions, (*path, d.name), seen)
            out.append(d)
            continue
        if isinstance(d, ast.TypedefGroup):
            keys = [(*path, name) for name, _pos, _dims in d.declarators]
            shapes = [(_signature(d.type), _signature(dims)) for _n, _p, dims in d.declarators]
        elif isinstance(d, ast.Struct | ast.Union_ | ast.Enum | ast.Const):
            keys, shapes = [(*path, d.name)], [_signature(d)]
        else:
            out.append(d)
            continue
        if all(k in seen and seen[k] == s for k, s in zip(keys, shapes, strict=True)):
            continue
        for k, s in zip(keys, shapes, strict=True):
            seen.setdefault(k, s)
        out.append(d)
    return out


def _signature(node: Any) -> Any:
    """What a declaration says, without where it says it: a nested tuple of its fields."""
    if isinstance(node, SourcePos):
        return None
    if isinstance(node, ast.Node):
        slots = [s for cls in type(node).__mro__ for s in getattr(cls, "__slots__", ())]
        return (
            type(node).__name__,
            tuple(_signature(getattr(node, s, None)) for s in sorted(set(slots) - _IGNORED)),
        )
    if isinstance(node, list | tuple):
        return tuple(_signature(x) for x in node)
    if isinstance(node, dict):
        return tuple(sorted((k, _signature(v)) for k, v in node.items()))
    return node
