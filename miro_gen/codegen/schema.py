"""Data schemas: the self-contained IDL text of a type and everything it uses.

The schema holds only modules, structs, unions, enums and typedefs, with array and sequence
bounds as literals, no includes or directives, no interfaces, and no leading `::`: the subset
that Foxglove's OMG IDL parser accepts, so that MCAP logs open in Foxglove. Declarations come in
dependency order, each wrapped in its modules; a type used recursively (through a sequence) is
forward-declared first. Exceptions are written as structs with the same members (only their data
matters here). A type declared inside a struct or union (`struct Outer { struct Inner {...} i; }`)
is written inside `module Outer`, unless the schema also holds `struct Outer`: then it is written
beside it as `Outer_Inner` (its Python class name), since the module would clash with the struct
and Foxglove's parser takes no declarations inside structs. The runtime hashes this text to check
types on the wire.
"""

from __future__ import annotations

from collections.abc import Callable

from miro_gen.idl import ast

OBJECT_REF = ("miro", "ObjectRef")
Dependency = ast.Decl | tuple[str, str]  # a declaration, or OBJECT_REF
_OBJECT_REF_TEXT = (
    "struct ObjectRef {\n  string repo_id;\n  string endpoint;\n  sequence<octet> key;\n};"
)


class _Collector:
    def __init__(self) -> None:
        self.order: list[
            tuple[str, ast.Decl | None]
        ] = []  # ("decl" | "forward" | "objectref", decl)
        self.done: set[int] = set()
        self.active: set[int] = set()
        self.forwarded: set[int] = set()

    def visit(self, decl: ast.Decl) -> None:
        decl = decl.resolved
        key = id(decl)
        if key in self.done:
            return
        if key in self.active:  # recursion through a sequence: declare it first
            if key not in self.forwarded:
                self.forwarded.add(key)
                self.order.append(("forward", decl))
            return
        self.active.add(key)
        for dep in _dependencies(decl):
            if isinstance(dep, ast.Decl):
                self.visit(dep)
            elif ("objectref", None) not in self.order:
                self.order.append(("objectref", None))
        self.active.discard(key)
        self.done.add(key)
        self.order.append(("decl", decl))


def _dependencies(decl: ast.Decl) -> list[Dependency]:
    match decl:
        case ast.Typedef():
            return _type_deps(decl.type)
        case ast.Struct():
            base = [decl.base] if decl.base is not None else []
            return base + [dep for m in decl.members for dep in _type_deps(m.type)]
        case ast.Exception_():
            return [dep for m in decl.members for dep in _type_deps(m.type)]
        case ast.Union_():
            cases = [dep for c in decl.cases for dep in _type_deps(c.type)]
            return _type_deps(decl.switch_type) + cases
    return []


def _type_deps(t: ast.TypeSpec) -> list[Dependency]:
    match t:
        case ast.NamedType():
            if t.decl is None:
                return []
            decl = t.decl.resolved
            return [OBJECT_REF] if decl.is_interface else [decl]
        case ast.SequenceType():
            return _type_deps(t.element)
        case ast.BaseType() if t.name == "Object":
            return [OBJECT_REF]
    return []


# Whether a scope path names a struct, union or exception of the schema (whose nested types are
# hoisted).
DataScope = Callable[[tuple[str, ...]], bool]


def _place(decl: ast.Decl, data_scope: DataScope) -> tuple[tuple[str, ...], str]:
    """The modules a declaration is written in, and its name there."""
    path = tuple(decl.scope_path)
    for i in range(1, len(path)):
        if data_scope(path[:i]):
            return path[: i - 1], "_".join(path[i - 1 :])
    return path[:-1], path[-1]


def _scoped(decl: ast.Decl, data_scope: DataScope) -> str:
    modules, name = _place(decl, data_scope)
    return "::".join((*modules, name))


def _type(t: ast.TypeSpec, data_scope: DataScope, refs: bool = False) -> str:
    """The IDL spelling of type `t`; object references as `miro::ObjectRef` (a data schema),
    or with `refs` as the interface they are (an interface schema)."""
    match t:
        case ast.BaseType():
            return "::".join(OBJECT_REF) if t.name == "Object" and not refs else t.name
        case ast.StringType():
            base = "wstring" if t.wide else "string"
            return f"{base}<{t.bound}>" if t.bound is not None else base
        case ast.SequenceType():
            elem = _type(t.element, data_scope, refs)
            return f"sequence<{elem}, {t.bound}>" if t.bound is not None else f"sequence<{elem}>"
        case ast.NamedType() if t.decl is not None:
            decl = t.decl.resolved
            if decl.is_interface:
                return decl.scoped_name if refs else "::".join(OBJECT_REF)
            return _scoped(decl, data_scope)
        case ast.FixedType():
            return f"fixed<{t.digits}, {t.scale}>"
        case ast.MapType():
            inner = f"{_type(t.key, data_scope, refs)}, {_type(t.value, data_scope, refs)}"
            return f"map<{inner}, {t.bound}>" if t.bound is not None else f"map<{inner}>"
    raise TypeError(f"not a data type: {t!r}")  # pragma: no cover


def _dims(dims: list[int]) -> str:
    return "".join(f"[{d}]" for d in dims)


def _label(v: ast.ConstValue, data_scope: DataScope) -> str:
    if isinstance(v, ast.EnumValue):  # enumerators live in the scope that holds their enum
        return "::".join((*_place(v.enum, data_scope)[0], v.name))
    if isinstance(v, bool):
        return "TRUE" if v else "FALSE"
    if isinstance(v, str):
        if v == "'" or v == "\\":
            return f"'\\{v}'"
        if v.isprintable() and ord(v) < 128:
            return f"'{v}'"
        return f"'\\x{ord(v):02x}'"
    return str(v)


def _body(decl: ast.Decl, data_scope: DataScope, refs: bool = False) -> str:
    """The declaration's text. With `refs` (an interface schema), object references keep
    their interfaces and exceptions stay exceptions."""
    name = _place(decl, data_scope)[1]
    match decl:
        case ast.Typedef():
            return f"typedef {_type(decl.type, data_scope, refs)} {name}{_dims(decl.dims)};"
        case ast.Enum():
            body = ",\n".join(f"  {e.name}" for e in decl.enumerators)
            return f"enum {name} {{\n{body}\n}};"
        case ast.Struct() | ast.Exception_():
            base = ""
            if isinstance(decl, ast.Struct) and decl.base is not None:
                base = f" : {_scoped(decl.base.resolved, data_scope)}"
            lines = [
                f"  {_type(m.type, data_scope, refs)} {m.name}{_dims(m.dims)};"
                for m in decl.members
            ]
            word = "exception" if refs and isinstance(decl, ast.Exception_) else "struct"
            return f"{word} {name}{base} {{\n" + "\n".join(lines) + ("\n" if lines else "") + "};"
        case ast.Union_():
            lines = [f"union {name} switch ({_type(decl.switch_type, data_scope)}) {{"]
            for c in decl.cases:
                for v in c.labels:
                    lines.append("  default:" if v is None else f"  case {_label(v, data_scope)}:")
                lines.append(f"    {_type(c.type, data_scope, refs)} {c.name}{_dims(c.dims)};")
            lines.append("};")
            return "\n".join(lines)
    raise TypeError(f"not a data type: {decl!r}")  # pragma: no cover


def _wrap(path: tuple[str, ...], text: str) -> str:
    """`text` inside `module A { module B { ... }; };` for scope path (A, B)."""
    for depth, name in reversed(list(enumerate(path))):
        del depth
        inner = "\n".join("  " + line if line else line for line in text.split("\n"))
        text = f"module {name} {{\n{inner}\n}};"
    return text


def data_schema(decl: ast.Decl) -> str:
    """The flattened IDL text of `decl` (a struct, union or exception) and its dependencies."""
    c = _Collector()
    c.visit(decl)
    data_types = {
        tuple(d.scope_path)
        for kind, d in c.order
        if kind == "decl" and isinstance(d, ast.Struct | ast.Union_ | ast.Exception_)
    }
    data_scope: DataScope = data_types.__contains__
    parts: list[str] = []
    for kind, d in c.order:
        if d is None:  # the object reference struct
            parts.append(_wrap(OBJECT_REF[:-1], _OBJECT_REF_TEXT))
        elif kind == "forward":
            word = "union" if isinstance(d, ast.Union_) else "struct"
            modules, name = _place(d, data_scope)
            parts.append(_wrap(modules, f"{word} {name};"))
        else:
            parts.append(_wrap(_place(d, data_scope)[0], _body(d, data_scope)))
    return "\n".join(parts) + "\n"
