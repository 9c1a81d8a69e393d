"""IDL parser: the LALR grammar in `grammar.lark` and a transformer that builds the AST while
parsing (no parse tree is built).

Lark compiles the grammar into tables (cached per user); `engine.Engine` runs them and calls this
module's `_AstBuilder` for each rule, by rule or alias name, as a Lark transformer would be called.
Doc comments are collected while scanning and attached afterwards to the declaration whose name
follows them (or, for `///<`-style comments, the one before).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from miro_gen.cache import cache_dir
from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.build_leaves import Children, LeafBuilder, Token
from miro_gen.idl.doc_comments import attach_docs
from miro_gen.idl.engine import Engine, ParseFailure, load_tables
from miro_gen.idl.keywords import RESERVED, UNSUPPORTED_CONSTRUCTS
from miro_gen.idl.source_text import SourceText

GRAMMAR_PATH = Path(__file__).with_name("grammar.lark")


class _AstBuilder(LeafBuilder):
    """Callbacks, one per grammar rule or alias, building `ast` nodes while parsing: the
    declarations here, the leaves (names, expressions, literals, types, annotations) in
    `LeafBuilder`."""

    # -- top level ----------------------------------------------------------------------------
    def start(self, c: Children) -> list[Any]:
        return c

    def annotated(self, c: Children) -> Any:
        node = c[-1]
        if isinstance(node, (ast.Pragma, ast.TypeIdDcl)):
            self.diag.error(c[0].pos, "annotations cannot be applied here")
        else:
            node.annotations = c[:-1] + node.annotations
        return node

    def pragma(self, c: Children) -> ast.Pragma:
        tok = c[0]
        return ast.Pragma(str(tok), self.pos(tok), self.instance(tok))

    def module(self, c: Children) -> ast.Module:
        _kw, name, *defs = c
        node = ast.Module(self.ident(name), self.pos(name), defs, instance=self.instance(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    # -- interfaces ---------------------------------------------------------------------------
    def interface_dcl(self, c: Children) -> ast.Interface:
        qual, _kw, name, bases, *body = c
        node = ast.Interface(
            self.ident(name),
            self.pos(name),
            abstract=qual is not None and qual.type == "ABSTRACT",
            local=qual is not None and qual.type == "LOCAL",
            base_names=bases or [],
            body=body,
            instance=self.instance(name),
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def forward_dcl(self, c: Children) -> ast.Forward:
        qual, _kw, name = c
        node = ast.Forward(
            self.ident(name),
            self.pos(name),
            of="interface",
            abstract=qual is not None and qual.type == "ABSTRACT",
            local=qual is not None and qual.type == "LOCAL",
            instance=self.instance(name),
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def interface_inheritance(self, c: Children) -> list[ast.ScopedName]:
        return [n.name for n in c]

    def op_dcl(self, c: Children) -> ast.Operation:
        oneway, ret, name, params, raises, contexts = c
        node = ast.Operation(
            self.ident(name),
            self.pos(name),
            oneway is not None,
            None if isinstance(ret, Token) else ret,
            params or [],
            raises or [],
            contexts or [],
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def params(self, c: Children) -> list[ast.Param]:
        return c

    def param_dcl(self, c: Children) -> ast.Param:
        *anns, mode, typ, name = c
        node = ast.Param(str(mode), typ, self.ident(name), self.pos(name), anns)
        return self.declared(name, node)  # type: ignore[no-any-return]

    def raises_expr(self, c: Children) -> list[ast.ScopedName]:
        return [n.name for n in c[1:]]

    def context_expr(self, c: Children) -> list[str]:
        out = []
        for tok in c[1:]:
            out.append(self.string_value(tok))
        return out

    def exception_list(self, c: Children) -> list[ast.ScopedName]:
        return [n.name for n in c]

    def _attr_group(
        self,
        typ: ast.TypeSpec,
        readonly: bool,
        names: list[Token],
        get_raises: list[ast.ScopedName],
        set_raises: list[ast.ScopedName],
    ) -> ast.AttributeGroup:
        group = ast.AttributeGroup(
            typ,
            readonly,
            [(self.ident(t), self.pos(t)) for t in names],
            get_raises,
            set_raises,
        )
        return self.declared(names[0], group)  # type: ignore[no-any-return]

    def readonly_attr(self, c: Children) -> ast.AttributeGroup:
        _ro, _kw, typ, name, raises = c
        return self._attr_group(typ, True, [name], raises or [], [])

    def readonly_attrs(self, c: Children) -> ast.AttributeGroup:
        _ro, _kw, typ, *names = c
        return self._attr_group(typ, True, names, [], [])

    def attr_raises_dcl(self, c: Children) -> ast.AttributeGroup:
        _kw, typ, name, (get_r, set_r) = c
        return self._attr_group(typ, False, [name], get_r, set_r)

    def attrs(self, c: Children) -> ast.AttributeGroup:
        _kw, typ, *names = c
        return self._attr_group(typ, False, names, [], [])

    def attr_raises(self, c: Children) -> tuple[list[ast.ScopedName], list[ast.ScopedName]]:
        if c[0].type == "GETRAISES":
            return c[1], (c[3] if len(c) > 3 and c[3] is not None else [])
        return [], c[1]

    # -- value types --------------------------------------------------------------------------
    def value_forward_dcl(self, c: Children) -> ast.Forward:
        abstract, _kw, name = c
        node = ast.Forward(
            self.ident(name),
            self.pos(name),
            of="valuetype",
            abstract=abstract is not None,
            instance=self.instance(name),
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def value_box_dcl(self, c: Children) -> ast.ValueBox:
        _kw, name, typ = c
        node = ast.ValueBox(self.ident(name), self.pos(name), typ, instance=self.instance(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    def _value(self, name: Token, inh: Any, body: list[Any], **kw: Any) -> ast.ValueType:
        (truncatable, bases), supports = inh
        node = ast.ValueType(
            self.ident(name),
            self.pos(name),
            truncatable=truncatable,
            base_names=bases,
            supports_names=supports,
            body=body,
            instance=self.instance(name),
            **kw,
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def value_abs_dcl(self, c: Children) -> ast.ValueType:
        _abs, _kw, name, inh, *body = c
        return self._value(name, inh, body, abstract=True)

    def value_dcl(self, c: Children) -> ast.ValueType:
        custom, _kw, name, inh, *body = c
        return self._value(name, inh, body, custom=custom is not None)

    def value_inheritance(self, c: Children) -> tuple[tuple[bool, list[Any]], list[Any]]:
        bases, supports = c
        return (bases or (False, [])), (supports or [])

    def value_bases(self, c: Children) -> tuple[bool, list[ast.ScopedName]]:
        trunc, *names = c
        return trunc is not None, [n.name for n in names]

    def value_supports(self, c: Children) -> list[ast.ScopedName]:
        return [n.name for n in c[1:]]

    def state_member(self, c: Children) -> ast.StateMemberGroup:
        anns, rest = _split_annotations(c)
        access, typ, *decls = rest
        group = ast.StateMemberGroup(
            str(access) == "public", typ, [d[:3] for d in decls], self.pos(access), anns
        )
        for d in decls:
            self.named.append((d[3], group))
            break
        return group

    def init_dcl(self, c: Children) -> ast.Factory:
        *anns, _kw, name, params, raises = c
        node = ast.Factory(self.ident(name), self.pos(name), params or [], raises or [], anns)
        return self.declared(name, node)  # type: ignore[no-any-return]

    def init_params(self, c: Children) -> list[ast.Param]:
        return c

    def init_param(self, c: Children) -> ast.Param:
        _mode, typ, name = c
        node = ast.Param("in", typ, self.ident(name), self.pos(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    def typeid_dcl(self, c: Children) -> ast.TypeIdDcl:
        kw, name, value = c
        return ast.TypeIdDcl(False, name.name, self.string_value(value), self.pos(kw))

    def typeprefix_dcl(self, c: Children) -> ast.TypeIdDcl:
        kw, name, value = c
        return ast.TypeIdDcl(True, name.name, self.string_value(value), self.pos(kw))

    # -- constants and expressions ------------------------------------------------------------
    def const_dcl(self, c: Children) -> ast.Const:
        _kw, typ, name, expr = c
        node = ast.Const(
            self.ident(name), self.pos(name), type=typ, expr=expr, instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    # -- types --------------------------------------------------------------------------------
    def typedef(self, c: Children) -> ast.TypedefGroup:
        kw, typ, *decls = c
        group = ast.TypedefGroup(
            typ, [d[:3] for d in decls], self.pos(kw), instance=self.instance(kw)
        )
        for d in decls:
            self.named.append((d[3], group))
            break
        return group

    def native(self, c: Children) -> ast.Native:
        _kw, name = c
        node = ast.Native(self.ident(name), self.pos(name), instance=self.instance(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    def struct_forward(self, c: Children) -> ast.Forward:
        _kw, name = c
        node = ast.Forward(
            self.ident(name), self.pos(name), of="struct", instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def union_forward(self, c: Children) -> ast.Forward:
        _kw, name = c
        node = ast.Forward(
            self.ident(name), self.pos(name), of="union", instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def declarator(self, c: Children) -> tuple[str, SourcePos, list[Any], int]:
        name, *dims = c
        return (self.ident(name), self.pos(name), dims, name.start_pos)

    def _members(self, anns: list[Any], typ: Any, decls: list[Any]) -> list[ast.Member]:
        out = []
        for name, pos, dims, start in decls:
            m = ast.Member(name, typ, dims, pos, list(anns))
            self.named.append((start, m))
            out.append(m)
        return out

    def struct_type(self, c: Children) -> ast.Struct:
        _kw, name, base, *items = c
        members, pragmas = _members_and_pragmas(items)
        node = ast.Struct(
            self.ident(name),
            self.pos(name),
            base_name=base.name if base is not None else None,
            members=members,
            instance=self.instance(name),
            pragmas=pragmas,
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def member(self, c: Children) -> list[ast.Member]:
        anns, rest = _split_annotations(c)
        return self._members(anns, rest[0], rest[1:])

    def union_type(self, c: Children) -> ast.Union_:
        _kw, name, _sw, *rest = c
        i = 0
        while isinstance(rest[i], ast.Annotation):
            i += 1
        switch_anns, switch_type, items = rest[:i], rest[i], rest[i + 1 :]
        node = ast.Union_(
            self.ident(name),
            self.pos(name),
            switch_type=switch_type,
            cases=[x for x in items if not isinstance(x, ast.Pragma)],
            switch_annotations=switch_anns,
            instance=self.instance(name),
            pragmas=[x for x in items if isinstance(x, ast.Pragma)],
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def case(self, c: Children) -> ast.CaseBranch:
        anns: list[ast.Annotation] = []
        labels: list[Any] = []
        typ: Any = None
        decl: Any = None
        for item in c:
            if isinstance(item, ast.Annotation):
                anns.append(item)
            elif isinstance(item, _Label):
                labels.append(item.expr)
            elif typ is None:
                typ = item
            else:
                decl = item
        name, pos, dims, start = decl
        branch = ast.CaseBranch(labels, name, typ, dims, pos, anns)
        self.named.append((start, branch))
        return branch

    def case_label(self, c: Children) -> _Label:
        return _Label(c[1] if c[0].type == "CASE" else None, self.pos(c[0]))

    def enum_type(self, c: Children) -> ast.Enum:
        _kw, name, *items = c
        enumerators = [x for x in items if not isinstance(x, ast.Pragma)]
        node = ast.Enum(
            self.ident(name),
            self.pos(name),
            enumerators=enumerators,
            instance=self.instance(name),
            pragmas=[x for x in items if isinstance(x, ast.Pragma)],
        )
        for i, e in enumerate(enumerators):
            e.enum = node
            e.ordinal = i
        return self.declared(name, node)  # type: ignore[no-any-return]

    def enumerator(self, c: Children) -> ast.Enumerator:
        *anns, name = c
        node = ast.Enumerator(
            self.ident(name), self.pos(name), annotations=anns, instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def except_dcl(self, c: Children) -> ast.Exception_:
        _kw, name, *items = c
        members, pragmas = _members_and_pragmas(items)
        node = ast.Exception_(
            self.ident(name),
            self.pos(name),
            members=members,
            instance=self.instance(name),
            pragmas=pragmas,
        )
        return self.declared(name, node)  # type: ignore[no-any-return]


def _members_and_pragmas(items: Children) -> tuple[list[ast.Member], list[ast.Pragma]]:
    """A struct or exception body: member groups (one list per line) and `#pragma` lines."""
    members = [m for x in items if not isinstance(x, ast.Pragma) for m in x]
    return members, [x for x in items if isinstance(x, ast.Pragma)]


def _split_annotations(c: Children) -> tuple[list[Any], list[Any]]:
    i = 0
    while i < len(c) and isinstance(c[i], ast.Annotation):
        i += 1
    return c[:i], c[i:]


class _Label:
    __slots__ = ("expr", "pos")

    def __init__(self, expr: Any, pos: SourcePos) -> None:
        self.expr = expr
        self.pos = pos


# ---- the parser -----------------------------------------------------------------------------

_lock = threading.Lock()
_engine: Engine | None = None
_builder = _AstBuilder()


def get_engine() -> Engine:
    global _engine
    if _engine is None:
        tables = load_tables(str(GRAMMAR_PATH), cache_dir())
        strings: dict[str, str] = tables["strings"]

        def describe(name: str) -> str:
            if name in _FRIENDLY:
                return _FRIENDLY[name]
            if name in strings:
                return f"'{strings[name]}'"
            return name.lower()

        _engine = Engine(tables, _builder, describe, UNSUPPORTED_CONSTRUCTS, RESERVED)
    return _engine


def parse(src: SourceText, diag: Diagnostics, case_sensitive: bool = False) -> list[Any] | None:
    """Parse preprocessed IDL into its top-level definitions; None after a syntax error.

    Problems found in well-formed syntax (a bad literal, a keyword used as a name) are reported
    but do not stop the parse, so the resolver can report its own problems too. With
    `case_sensitive`, an identifier clashes only with a keyword spelled exactly alike.
    """
    engine = get_engine()
    comments: list[tuple[int, str]] = []
    with _lock:
        _builder.begin(src, diag, case_sensitive)
        try:
            result = engine.parse(src.text, comments)
        except ParseFailure as e:
            diag.error(src.pos_at(e.offset), e.message)
            return None
        finally:
            named = _builder.named
            _builder.begin(SourceText("", [], []), Diagnostics())
    attach_docs(named, comments)
    return list(result)


_FRIENDLY = {
    "IDENT": "identifier",
    "INTEGER": "integer literal",
    "FLOAT": "floating-point literal",
    "FIXED": "fixed-point literal",
    "CHAR": "character literal",
    "WCHAR": "wide character literal",
    "STRING": "string literal",
    "WSTRING": "wide string literal",
    "PRAGMA": "#pragma",
    "$END": "end of file",
}
