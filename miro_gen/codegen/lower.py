"""Lowering: the module contexts of one IDL file of a resolved specification.

Each declaration of the file goes, by its AST node type, to the lowering of its kind
(`lower_data.py`, `lower_interface.py`), which returns its context; the context is appended to
the module its place names (`scope.py`). Declarations nested in an interface, struct or union
come before their container, whose class then names them as attributes.
"""

from __future__ import annotations

from miro_gen.codegen import names
from miro_gen.codegen.contexts import ModuleContext
from miro_gen.codegen.hints import TypeHints
from miro_gen.codegen.lower_data import DataLowering
from miro_gen.codegen.lower_interface import InterfaceLowering
from miro_gen.codegen.scope import Scope
from miro_gen.codegen.shapes import Unsupported
from miro_gen.idl import ast

# Declarations the back end refuses, and what the message calls them.
REFUSED = {ast.Native: "native type", ast.ValueType: "value type", ast.ValueBox: "value box"}


def lower_file(spec: ast.Specification, main_file: str, source: str) -> list[ModuleContext]:
    """The generated modules of `main_file` (one of the files of `spec`), sorted by name;
    `source` is how their headers name the IDL file."""
    return _Lowering(spec, source).file(main_file)


class _Lowering:
    def __init__(self, spec: ast.Specification, source: str) -> None:
        self.spec = spec
        self.scope = Scope(spec, source)
        hints = TypeHints(self.scope)
        self.data = DataLowering(self.scope, hints, spec.ros2_hashes)
        self.interfaces = InterfaceLowering(self.scope, hints, spec.declarations)
        # Class attributes each container gets for what is nested in it: (name, value).
        self.nested: dict[int, list[tuple[str, str]]] = {}

    def file(self, main_file: str) -> list[ModuleContext]:
        mine = [
            d
            for d in self.spec.declarations
            if d.pos.path == main_file and not isinstance(d, ast.Module | ast.Forward)
        ]
        for d in self._nested_first(mine):
            self._declare(d)
        return sorted(self.scope.modules.values(), key=lambda m: (m.package, m.stem))

    def _nested_first(self, decls: list[ast.Decl]) -> list[ast.Decl]:
        """Source order, except that declarations nested in an interface, struct or union come
        before their container (whose class refers to them)."""
        children: dict[int, list[ast.Decl]] = {}
        top: list[ast.Decl] = []
        for d in decls:
            container = self.scope.container(d)
            if container is not None:
                children.setdefault(id(container), []).append(d)
            else:
                top.append(d)
        out: list[ast.Decl] = []

        def visit(d: ast.Decl) -> None:
            for c in children.get(id(d), []):
                visit(c)
            out.append(d)

        for d in top:
            visit(d)
        return out

    def _declare(self, d: ast.Decl) -> None:
        m = self.scope.module(d)
        nested = self.nested.pop(id(d), [])
        match d:
            case ast.Enum():
                enum = self.data.enum(d, m, nested=self.scope.place(d).nesting > 0)
                m.add(enum, "E742")
                for e in enum.enumerators:
                    if e.module_constant:
                        m.exports.append(e.name)
                    else:
                        self._nest(d, e.name, f"{enum.name}.{e.name}")
            case ast.Struct():
                m.add(self.data.struct(d, m, nested), "E742")
            case ast.Union_():
                m.add(self.data.union(d, m, nested), "E742")
            case ast.Exception_():
                m.add(self.data.exception(d, m, nested), "E742")
            case ast.Typedef():
                m.add(self.data.typedef(d, m), "E741")
            case ast.Const():
                m.add(self.data.const(d, m), "E741")
            case ast.Interface():
                m.add(self.interfaces.stub(d, m, nested), "E742")
                poa = self.scope.module(d, poa=True)
                poa.add(self.interfaces.skeleton(d, poa), "E742")
            case ast.AnnotationDecl():
                return
            case _:
                what = REFUSED.get(type(d), d.kind)
                raise Unsupported(d.pos, f"{what} '{d.scoped_name}' cannot be generated for Python")
        self._nest(d, names.py_name(d.name), self.scope.place(d).cls)

    def _nest(self, d: ast.Decl, name: str, value: str) -> None:
        """Make a nested declaration (or enumerator) reachable as an attribute of its
        container class (containers are generated after what they contain)."""
        container = self.scope.container(d)
        if container is not None:
            self.nested.setdefault(id(container), []).append((name, value))
