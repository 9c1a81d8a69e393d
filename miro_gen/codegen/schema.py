"""Data schemas: the self-contained IDL text of a type and everything it uses.

The schema holds only modules, structs, unions, enums and typedefs, with array and sequence
bounds as literals, no includes or directives, no interfaces, and no leading `::`: the subset
that Foxglove's OMG IDL parser accepts, so that MCAP logs open in Foxglove. Declarations come in
dependency order, each wrapped in its modules; a type used recursively (through a sequence) is
forward-declared first. Exceptions are written as structs with the same members (only their data
matters here). The runtime hashes this text to check types on the wire.
"""

from __future__ import annotations

from typing import Any

from miro_gen.idl import ast

OBJECT_REF = ("miro", "ObjectRef")
_OBJECT_REF_TEXT = (
    "struct ObjectRef {\n  string repo_id;\n  string endpoint;\n  sequence<octet> key;\n};"
)


def _completed(node: Any) -> Any:
    if isinstance(node, ast.Forward) and node.full is not None:
        return node.full
    return node


class _Collector:
    def __init__(self) -> None:
        self.order: list[tuple[str, Any]] = []  # ("decl" | "forward" | "objectref", decl)
        self.done: set[int] = set()
        self.active: set[int] = set()
        self.forwarded: set[int] = set()

    def visit(self, decl: Any) -> None:
        decl = _completed(decl)
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
            if dep is OBJECT_REF:
                if ("objectref", None) not in self.order:
                    self.order.append(("objectref", None))
            else:
                self.visit(dep)
        self.active.discard(key)
        self.done.add(key)
        self.order.append(("decl", decl))


def _dependencies(decl: Any) -> list[Any]:
    out: list[Any] = []
    if isinstance(decl, ast.Typedef):
        out += _type_deps(decl.type)
    elif isinstance(decl, (ast.Struct, ast.Exception_)):
        if isinstance(decl, ast.Struct) and decl.base is not None:
            out.append(decl.base)
        for m in decl.members:
            out += _type_deps(m.type)
    elif isinstance(decl, ast.Union_):
        out += _type_deps(decl.switch_type)
        for c in decl.cases:
            out += _type_deps(c.type)
    return out


def _type_deps(t: Any) -> list[Any]:
    if isinstance(t, ast.NamedType):
        decl = _completed(t.decl)
        if isinstance(decl, ast.Interface) or (
            isinstance(decl, ast.Forward) and decl.of == "interface"
        ):
            return [OBJECT_REF]
        return [decl] if decl is not None else []
    if isinstance(t, ast.SequenceType):
        return _type_deps(t.element)
    if isinstance(t, ast.BaseType) and t.name == "Object":
        return [OBJECT_REF]
    return []


def _type(t: Any) -> str:
    if isinstance(t, ast.BaseType):
        return "::".join(OBJECT_REF) if t.name == "Object" else t.name
    if isinstance(t, ast.StringType):
        base = "wstring" if t.wide else "string"
        return f"{base}<{t.bound}>" if t.bound is not None else base
    if isinstance(t, ast.SequenceType):
        elem = _type(t.element)
        return f"sequence<{elem}, {t.bound}>" if t.bound is not None else f"sequence<{elem}>"
    if isinstance(t, ast.NamedType):
        decl = _completed(t.decl)
        if isinstance(decl, ast.Interface) or (
            isinstance(decl, ast.Forward) and decl.of == "interface"
        ):
            return "::".join(OBJECT_REF)
        return str(decl.scoped_name)
    if isinstance(t, ast.FixedType):
        return f"fixed<{t.digits}, {t.scale}>"
    if isinstance(t, ast.MapType):
        inner = f"{_type(t.key)}, {_type(t.value)}"
        return f"map<{inner}, {t.bound}>" if t.bound is not None else f"map<{inner}>"
    raise TypeError(f"not a data type: {t!r}")  # pragma: no cover


def _dims(dims: list[int]) -> str:
    return "".join(f"[{d}]" for d in dims)


def _label(v: Any) -> str:
    if isinstance(v, ast.EnumValue):
        return v.scoped_name
    if isinstance(v, bool):
        return "TRUE" if v else "FALSE"
    if isinstance(v, str):
        if v == "'" or v == "\\":
            return f"'\\{v}'"
        if v.isprintable() and ord(v) < 128:
            return f"'{v}'"
        return f"'\\x{ord(v):02x}'"
    return str(v)


def _body(decl: Any) -> str:
    name = decl.name
    if isinstance(decl, ast.Typedef):
        return f"typedef {_type(decl.type)} {name}{_dims(decl.dims)};"
    if isinstance(decl, ast.Enum):
        return f"enum {name} {{\n" + ",\n".join(f"  {e.name}" for e in decl.enumerators) + "\n};"
    if isinstance(decl, (ast.Struct, ast.Exception_)):
        members = decl.members
        base = ""
        if isinstance(decl, ast.Struct) and decl.base is not None:
            base = f" : {decl.base.scoped_name}"
        lines = [f"  {_type(m.type)} {m.name}{_dims(m.dims)};" for m in members]
        return f"struct {name}{base} {{\n" + "\n".join(lines) + ("\n" if lines else "") + "};"
    if isinstance(decl, ast.Union_):
        lines = [f"union {name} switch ({_type(decl.switch_type)}) {{"]
        for c in decl.cases:
            for v in c.labels:
                lines.append("  default:" if v is None else f"  case {_label(v)}:")
            lines.append(f"    {_type(c.type)} {c.name}{_dims(c.dims)};")
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


def data_schema(decl: Any) -> str:
    """The flattened IDL text of `decl` (a struct, union or exception) and its dependencies."""
    c = _Collector()
    c.visit(decl)
    parts: list[str] = []
    for kind, d in c.order:
        if kind == "objectref":
            parts.append(_wrap(OBJECT_REF[:-1], _OBJECT_REF_TEXT))
        elif kind == "forward":
            word = "union" if isinstance(d, ast.Union_) else "struct"
            parts.append(_wrap(d.scope_path[:-1], f"{word} {d.name};"))
        else:
            parts.append(_wrap(d.scope_path[:-1], _body(d)))
    return "\n".join(parts) + "\n"
