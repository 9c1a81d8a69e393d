"""Where each declaration of a specification lives in Python, and how to refer to it.

A `Place` is a declaration's generated module (and skeleton module) and its class name there;
the `Scope` of a specification knows every declaration's place, makes the `ModuleContext` of
each generated module, and spells references from one module to a class of another, recording
the import in the referring module (always passed explicitly).
"""

from __future__ import annotations

from dataclasses import dataclass

from miro_gen.codegen import names
from miro_gen.codegen.contexts import ModuleContext
from miro_gen.codegen.shapes import Unsupported
from miro_gen.idl import ast


@dataclass(frozen=True)
class Place:
    """Where a declaration lives in Python: module, class name, nesting."""

    idl_module: tuple[str, ...]  # the IDL module it is declared in
    nesting: int  # interfaces, structs or unions it is nested in
    module: str  # the generated module, Miro.Example_idl
    poa_module: str  # the skeleton module, Miro__POA.Example_idl
    cls: str  # its module-level name, Outer_Inner


class Scope:
    """The places of the declarations of one specification, and the modules they go to."""

    def __init__(self, spec: ast.Specification, source: str) -> None:
        self.source = source
        module_paths = {d.scope_path for d in spec.declarations if isinstance(d, ast.Module)}
        self._places: dict[int, Place] = {}
        stems: dict[str, str] = {}  # IDL file -> module stem
        modules: dict[tuple[tuple[str, ...], str], tuple[str, str]] = {}  # (IDL module, stem)
        for d in spec.declarations:
            outer = d.scope_path[:-1]
            while outer and outer not in module_paths:
                outer = outer[:-1]
            stem = stems.get(d.pos.path)
            if stem is None:
                stem = stems[d.pos.path] = names.module_stem(d.pos.path)
            module = modules.get((outer, stem))
            if module is None:
                module = modules[outer, stem] = (
                    f"{names.package_name(outer)}.{stem}",
                    f"{names.poa_package_name(outer)}.{stem}",
                )
            nesting = len(d.scope_path) - 1 - len(outer)
            self._places[id(d)] = Place(outer, nesting, *module, names.class_name(d, nesting))
        self._by_path = {
            d.scope_path: d for d in spec.declarations if not isinstance(d, ast.Forward)
        }
        self.modules: dict[str, ModuleContext] = {}

    def find(self, decl: ast.Decl) -> Place | None:
        return self._places.get(id(decl))

    def place(self, decl: ast.Decl) -> Place:
        place = self._places.get(id(decl))
        if place is None:  # pragma: no cover - every declaration has a place
            raise Unsupported(decl.pos, f"no Python name for {decl.scoped_name}")
        return place

    def container(self, decl: ast.Decl) -> ast.Decl | None:
        """The interface, struct or union a nested declaration is declared in."""
        if not self.place(decl).nesting:
            return None
        return self._by_path.get(decl.scope_path[:-1])

    def module(self, decl: ast.Decl, poa: bool = False) -> ModuleContext:
        """The context of the module a declaration (or its skeleton) is generated into."""
        place = self.place(decl)
        name = place.poa_module if poa else place.module
        m = self.modules.get(name)
        if m is None:
            package, stem = name.rsplit(".", 1)
            m = ModuleContext(package, stem, self.source, "::".join(place.idl_module), poa=poa)
            self.modules[name] = m
        return m

    def ref(self, decl: ast.Decl, m: ModuleContext, poa: bool = False, fmt: str = "{}") -> str:
        """The Python expression, in module `m`, for a declaration's class (its skeleton with
        `poa`), or for a module-level name made from the class name by `fmt` (`_enc_{}`)."""
        place = self.place(decl.resolved)
        return m.reference(place.poa_module if poa else place.module, fmt.format(place.cls))
