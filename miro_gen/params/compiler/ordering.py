"""The order of a module's classes: each after its base and the structures it holds.

A class needs its base and the classes of its structure fields defined before it; the element
class of a vector may come later (a vector starts empty): such a reference, and a vector of the
class itself (makeParams' recursive `FilterTree`), is made lazy (`_rt.Struct(lambda: X)`). A class
that holds itself (or a cycle of classes holding each other) outside vectors is refused, as C++
refused it.
"""

from __future__ import annotations

from miro_gen.diagnostics import Diagnostics
from miro_gen.params.compiler.pymodel import PyClass, PyType


def defined_name(c: PyClass) -> str:
    """The module-level name a class (or an IDL struct's layout) is defined under."""
    return f"{c.name}_xml" if c.dummy_target is not None else c.name


def _needs(c: PyClass, local: set[str]) -> list[tuple[str, bool]]:
    """(local name, through a vector) of what a class refers to."""
    out: list[tuple[str, bool]] = []
    if c.base in local:
        out.append((c.base, False))
    for f in c.fields + c.constants:
        for t in f.type.structs():
            if t.struct_target in local:
                out.append((t.struct_target, t is not f.type))
    return out


def order_classes(classes: list[PyClass], diag: Diagnostics) -> list[PyClass]:
    """Source order, except that a class comes after the local classes it needs."""
    by_name = {defined_name(c): c for c in classes}
    local = set(by_name)
    done: list[PyClass] = []
    state: dict[str, int] = {}

    def visit(c: PyClass) -> None:
        name = defined_name(c)
        mark = state.get(name)
        if mark == 2:
            return
        if mark == 1:
            diag.error(c.decl.pos, f"{c.name} contains itself (recursive parameter types)")
            return
        state[name] = 1
        for needed, through_vector in _needs(c, local):
            if through_vector and state.get(needed) == 1:
                continue  # a vector of a class being defined: lazy below
            visit(by_name[needed])
        state[name] = 2
        done.append(c)

    for c in classes:
        visit(c)
    defined: set[str] = set()
    for c in done:
        for f in c.fields + c.constants:
            for t in f.type.structs():
                _mark_lazy(t, local, defined)
        defined.add(defined_name(c))
    return done


def _mark_lazy(t: PyType, local: set[str], defined: set[str]) -> None:
    if t.struct_target in local and t.struct_target not in defined:
        t.lazy = True
