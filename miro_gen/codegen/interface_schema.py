"""Interface schemas: the self-contained IDL text of an interface, for callers without its IDL.

A server answers `MiroService::Service::interface_schema(repo_id)` with this text (see
docs/PROTOCOL.md, "The service object"), so that `miro call` and `miro list` can call and show
any object from the shell with no generated code of their own: the text compiles, with
miro-idl alone, into a stub that talks to the server, types whose data schemas (and so type
hashes) are the server's, and exceptions with the server's repository ids.

It holds the interface, its bases, every interface its operations and attributes pass by
reference, the exceptions they raise and the data types they use, in dependency order and with
evaluated bounds, like a data schema (schema.py) but keeping interfaces and exceptions for what
they are. Declarations nested in an interface are written inside it. A repository id that is
not the default one for its name (`#pragma prefix`, `#pragma ID`) is restated with a `typeid`
after the declaration (and after its forward declaration).
A type declared inside a struct or union cannot be written without renaming it: such
interfaces have no schema (`NoInterfaceSchema`).
"""

from __future__ import annotations

from typing import Any

from miro_gen.codegen.schema import _body, _type, _wrap
from miro_gen.idl import ast

LINE = 60  # characters of an operation's declaration before its parameters go one per line


class NoInterfaceSchema(Exception):
    """The interface uses something an interface schema cannot state."""


def _no_data_scope(path: tuple[str, ...]) -> bool:
    return False


def _typeid(decl: Any) -> list[str]:
    """`typeid` for a repository id that is not the default one of the name (none else)."""
    if not decl.repo_id or decl.repo_id == f"IDL:{'/'.join(decl.scope_path)}:1.0":
        return []
    return [f'typeid {decl.name} "{decl.repo_id}";']


def _declare(decl: Any, text: str) -> str:
    """`text` (the declaration) and its typeid, in the declaration's modules."""
    return _wrap(tuple(decl.scope_path[:-1]), "\n".join([text, *_typeid(decl)]))


class InterfaceSchemas:
    """The interface schemas of one specification. Its declarations are indexed once (by
    scoped path, and by the path of what they are declared in), however many interfaces it has:
    a compilation's work stays linear in its declarations."""

    def __init__(self, declarations: list[ast.Decl]) -> None:
        self.by_path: dict[tuple[str, ...], ast.Decl] = {}
        self.children: dict[tuple[str, ...], list[ast.Decl]] = {}
        for d in declarations:
            if isinstance(d, ast.Forward):
                continue
            self.by_path[d.scope_path] = d
            if not isinstance(d, ast.Module):
                self.children.setdefault(tuple(d.scope_path[:-1]), []).append(d)
        # The text of each declaration as schemas state it (in its modules): the same in every
        # schema that holds it, so written once.
        self.texts: dict[int, str] = {}

    def of(self, decl: ast.Interface) -> str:
        """The interface schema of `decl`; NoInterfaceSchema when it cannot be written."""
        w = _Writer(self)
        w.interface(decl)
        while w.pending:
            w.interface(w.pending.pop(0))
        return "\n".join(w.parts) + "\n"


class _Writer:
    def __init__(self, index: InterfaceSchemas) -> None:
        self.by_path = index.by_path
        self.children = index.children
        self.texts = index.texts
        self.parts: list[str] = []
        self.done: set[int] = set()
        self.active: list[Any] = []
        self.forwarded: set[int] = set()
        self.pending: list[Any] = []

    # ---- what is needed -------------------------------------------------------------------------

    def need_type(self, t: Any) -> None:
        if isinstance(t, ast.SequenceType):
            self.need_type(t.element)
        elif isinstance(t, ast.MapType):
            self.need_type(t.key)
            self.need_type(t.value)
        elif isinstance(t, ast.NamedType):
            decl = t.decl.resolved if t.decl is not None else None
            if decl is not None and decl.is_interface:
                self.refer(decl)
            elif decl is not None:
                self.need_decl(decl)

    def refer(self, iface: Any) -> None:
        """An interface passed by reference: declared before use, defined at some point."""
        if id(iface) in self.done or (self.active and self.active[-1] is iface):
            return
        if id(iface) not in self.forwarded:
            self.forwarded.add(id(iface))
            word = "local interface" if getattr(iface, "local", False) else "interface"
            self.parts.append(_declare(iface, f"{word} {iface.name};"))
        if isinstance(iface, ast.Interface):
            self.pending.append(iface)

    def container(self, decl: Any) -> Any:
        return self.by_path.get(tuple(decl.scope_path[:-1]))

    def need_decl(self, decl: Any) -> None:
        outer = self.container(decl)
        if isinstance(outer, ast.Interface):
            self.interface(outer)
            return
        if isinstance(outer, ast.Struct | ast.Union_ | ast.Exception_):
            raise NoInterfaceSchema(f"{decl.scoped_name} is declared inside {outer.scoped_name}")
        if id(decl) in self.done:
            return
        at = next((i for i, d in enumerate(self.active) if d is decl), None)
        if at is not None:  # recursion through a sequence
            if not isinstance(decl, ast.Typedef):
                self.forward(decl)
                return
            # typedef sequence<S> T inside struct S: S declared first, then T at once
            inner = [d for d in self.active[at:] if isinstance(d, ast.Struct | ast.Union_)]
            if inner:
                self.forward(inner[0])
            self.write(decl)
            return
        self.active.append(decl)
        self.data_deps(decl)
        self.active.pop()
        if id(decl) not in self.done:
            self.write(decl)

    def forward(self, decl: Any) -> None:
        if id(decl) not in self.forwarded:
            self.forwarded.add(id(decl))
            word = "union" if isinstance(decl, ast.Union_) else "struct"
            self.parts.append(_declare(decl, f"{word} {decl.name};"))

    def write(self, decl: Any) -> None:
        self.done.add(id(decl))
        text = self.texts.get(id(decl))
        if text is None:
            text = self.texts[id(decl)] = _declare(decl, _body(decl, _no_data_scope, refs=True))
        self.parts.append(text)

    def data_deps(self, decl: Any) -> None:
        if isinstance(decl, ast.Typedef):
            self.need_type(decl.type)
        elif isinstance(decl, ast.Struct | ast.Exception_):
            if isinstance(decl, ast.Struct) and decl.base is not None:
                self.need_decl(decl.base.resolved)
            for m in decl.members:
                self.need_type(m.type)
        elif isinstance(decl, ast.Union_):
            self.need_type(decl.switch_type)
            for c in decl.cases:
                self.need_type(c.type)

    # ---- interfaces -----------------------------------------------------------------------------

    def interface(self, iface: Any) -> None:
        if id(iface) in self.done or any(d is iface for d in self.active):
            return
        self.active.append(iface)
        for base in iface.bases:
            self.interface(base.resolved)
        nested = [
            d
            for d in self.children.get(tuple(iface.scope_path), [])
            if isinstance(d, ast.Struct | ast.Union_ | ast.Enum | ast.Typedef | ast.Exception_)
        ]
        for d in nested:
            self.data_deps(d)
        for op in iface.operations:
            if op.returns is not None:
                self.need_type(op.returns)
            for p in op.params:
                self.need_type(p.type)
            for e in op.raises:
                self.need_decl(e)
        for a in iface.attributes:
            self.need_type(a.type)
            for e in [*a.get_raises, *a.set_raises]:
                self.need_decl(e)
        self.active.pop()
        self.done.add(id(iface))
        for d in nested:
            self.done.add(id(d))
        text = self.texts.get(id(iface))
        if text is None:
            text = self.texts[id(iface)] = _declare(iface, self.interface_text(iface, nested))
        self.parts.append(text)

    def interface_text(self, iface: Any, nested: list[Any]) -> str:
        word = "abstract interface" if iface.abstract else "interface"
        if iface.local:
            word = "local interface"
        bases = [b.resolved.scoped_name for b in iface.bases]
        head = f"{word} {iface.name}" + (f" : {', '.join(bases)}" if bases else "") + " {"
        lines: list[str] = []
        for d in nested:
            text = "\n".join([_body(d, _no_data_scope, refs=True), *_typeid(d)])
            lines += ["  " + line for line in text.split("\n")]
        for a in iface.attributes:
            lines.append("  " + self.attribute_text(a))
        for op in iface.operations:
            lines += ["  " + line for line in self.operation_text(op).split("\n")]
        return "\n".join([head, *lines, "};"])

    @staticmethod
    def operation_text(op: Any) -> str:
        """One line, or one line per parameter when that is long (generated code keeps the
        schema's lines, and its lines must stay short)."""
        returns = "void" if op.returns is None else _type(op.returns, _no_data_scope, True)
        params = [f"{p.mode} {_type(p.type, _no_data_scope, True)} {p.name}" for p in op.params]
        head = f"{'oneway ' if op.oneway else ''}{returns} {op.name}("
        raises = f" raises ({', '.join(e.scoped_name for e in op.raises)})" if op.raises else ""
        text = head + ", ".join(params) + ")" + raises + ";"
        if len(text) <= LINE and "\n" not in text:
            return text
        lines = [head, *(f"    {p}," for p in params)]
        lines[-1] = lines[-1].rstrip(",") + ")" if params else lines[-1] + ")"
        if raises:
            lines.append(f"    {raises.strip()}")
        lines[-1] += ";"
        return "\n".join(lines)

    @staticmethod
    def attribute_text(a: Any) -> str:
        text = f"{'readonly ' if a.readonly else ''}attribute {_type(a.type, _no_data_scope, True)}"
        text += f" {a.name}"
        if a.readonly and a.get_raises:
            text += f" raises ({', '.join(e.scoped_name for e in a.get_raises)})"
        else:
            if a.get_raises:
                text += f" getraises ({', '.join(e.scoped_name for e in a.get_raises)})"
            if a.set_raises:
                text += f" setraises ({', '.join(e.scoped_name for e in a.set_raises)})"
        return text + ";"


def interface_schema(decl: ast.Interface, declarations: list[ast.Decl]) -> str:
    """The interface schema of `decl`; `declarations` are those of the resolved specification
    (for what is nested in interfaces). NoInterfaceSchema when it cannot be written. For many
    interfaces of one specification, `InterfaceSchemas` indexes the declarations once."""
    return InterfaceSchemas(declarations).of(decl)
