"""Valid IDL that generated Python cannot hold, found before the modules are written and refused
with the construct and its position, so that no generated module fails when it is imported.

* Interface inheritance becomes class inheritance: a base that another listed base already
  inherits is left out of the class statement (`interface five : four, three, two` where four
  inherits two and three is `class five(four)`), and an inheritance graph Python cannot order
  (`interface C : A, B` with A : X, Y and B : Y, X) is refused.
* Generated modules import each other; a cycle of imports is harmless unless a class of one
  module is the base of a class in another module of the cycle: that module may be imported
  while its base's module is still half-initialised. Such cycles are refused.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from miro_gen.codegen.contexts import ModuleContext
from miro_gen.codegen.shapes import Unsupported
from miro_gen.idl import ast

# Nested declarations that become classes: redeclared, they would differ in type.
_CLASS_KINDS = (ast.Struct, ast.Union_, ast.Exception_, ast.Enum)


def python_bases(bases: list[ast.Interface]) -> list[ast.Interface]:
    """The bases of an interface's Python classes: those no other listed base inherits."""
    inherited: set[int] = set()
    for b in bases:
        inherited.update(id(a) for a in _ancestors(b))
    return [b for b in bases if id(b) not in inherited]


def check_inheritance(declarations: Iterable[ast.Decl]) -> None:
    """Raise `Unsupported` for the first interface whose classes Python cannot order."""
    orders: dict[int, list[ast.Interface] | None] = {}
    for d in declarations:
        if isinstance(d, ast.Interface) and _linearize(d, orders) is None:
            names = ", ".join(b.scoped_name for b in python_bases(d.bases))
            raise Unsupported(
                d.pos,
                f"interface '{d.scoped_name}' cannot be generated for Python: the orders in which "
                f"its bases ({names}) inherit their own bases conflict, so Python cannot order "
                "its classes",
            )


def check_nested_names(mine: Iterable[ast.Decl], everything: list[ast.Decl]) -> None:
    """Raise `Unsupported` for an interface whose class would get two different classes for one
    class attribute: a struct, union, exception or enum (or an enumerator) declared in it that a
    base declares too (IDL lets a derived interface redeclare it), or one declared in two
    unrelated bases."""
    nested: dict[tuple[str, ...], dict[str, ast.Decl]] = {}
    for d in everything:
        if not isinstance(d, _CLASS_KINDS) or len(d.scope_path) < 2:
            continue  # typedefs and constants may be redeclared: attributes of compatible types
        names = nested.setdefault(d.scope_path[:-1], {})
        names[d.name] = d
        if isinstance(d, ast.Enum):
            for e in d.enumerators:
                names[e.name] = d
    for d in mine:
        if not isinstance(d, ast.Interface):
            continue
        own = nested.get(d.scope_path, {})
        seen: dict[str, ast.Interface] = {}
        for base in _ancestors(d):
            for name in nested.get(base.scope_path, {}):
                if name in own:
                    raise Unsupported(
                        own[name].pos,
                        f"'{d.scoped_name}::{name}' cannot be generated for Python: it redeclares "
                        f"'{base.scoped_name}::{name}' of a base interface, and the two would be "
                        "one class attribute of different types",
                    )
                other = seen.setdefault(name, base)
                if (
                    other is not base
                    and base not in _ancestors(other)
                    and other not in (_ancestors(base))
                ):
                    raise Unsupported(
                        d.pos,
                        f"interface '{d.scoped_name}' cannot be generated for Python: its bases "
                        f"'{other.scoped_name}' and '{base.scoped_name}' both declare '{name}', "
                        "which would be one class attribute of different types",
                    )


def base_class_cycles(
    modules: list[ModuleContext], declarations: dict[str, ast.Decl]
) -> list[tuple[Any, str]]:
    """(position, message) for each class whose base comes from a module that imports, directly
    or not, the module of the class: importing one of them first fails. `declarations` gives
    each item's declaration by scoped name (for its position)."""
    imports = {m.name: set(m.imports) for m in modules}
    out: list[tuple[Any, str]] = []
    for m in modules:
        alias_to_module = {alias: module for module, alias in m.imports.items()}
        for item in m.items:
            for base in getattr(item, "bases", ()):
                alias = base.split(".", 1)[0]
                other = alias_to_module.get(alias)
                decl = declarations.get(item.scoped_name)
                if decl is None or other is None or other not in imports:
                    continue
                if _reaches(other, m.name, imports):
                    out.append(
                        (
                            decl.pos,
                            f"'{item.scoped_name}' cannot be generated for Python: its base "
                            f"comes from the generated module {other}, which imports {m.name} in "
                            "turn (IDL modules that use each other's interfaces and inherit "
                            "across them); declare the two interfaces in one IDL module",
                        )
                    )
    return out


def _ancestors(i: ast.Interface) -> list[ast.Interface]:
    out: list[ast.Interface] = []
    todo = list(i.bases)
    while todo:  # breadth first, in the order the bases are listed
        b = todo.pop(0)
        if all(b is not a for a in out):
            out.append(b)
            todo.extend(b.bases)
    return out


def _linearize(
    i: ast.Interface, orders: dict[int, list[ast.Interface] | None]
) -> list[ast.Interface] | None:
    """Python's method resolution order (C3) of the interface's stub class, or None."""
    if id(i) in orders:
        return orders[id(i)]
    orders[id(i)] = None  # inheritance cycles are errors in the front end; stop if one slips by
    bases = python_bases(i.bases)
    lists: list[list[ast.Interface]] = []
    for b in bases:
        order = _linearize(b, orders)
        if order is None:
            return None
        lists.append(list(order))
    lists.append(list(bases))
    result: list[ast.Interface] = [i]
    while any(lists):
        for candidate in (lst[0] for lst in lists if lst):
            if not any(candidate in lst[1:] for lst in lists):
                break
        else:
            return None
        result.append(candidate)
        lists = [lst[1:] if lst and lst[0] is candidate else lst for lst in lists]
    orders[id(i)] = result
    return result


def _reaches(start: str, goal: str, imports: dict[str, set[str]]) -> bool:
    seen: set[str] = set()
    todo = [start]
    while todo:
        m = todo.pop()
        if m == goal:
            return True
        if m not in seen:
            seen.add(m)
            todo.extend(imports.get(m, ()))
    return False
