"""IDL parser: the LALR grammar in `grammar.lark` and a transformer that builds the AST while
parsing (no parse tree is built).

Lark compiles the grammar into tables (cached per user); `engine.Engine` runs them and calls this
module's `_AstBuilder` for each rule, by rule or alias name, as a Lark transformer would be called.
Doc comments are collected while scanning and attached afterwards to the declaration whose name
follows them (or, for `///<`-style comments, the one before).
"""

from __future__ import annotations

import threading
from bisect import bisect_left
from pathlib import Path
from typing import Any

from miro_gen.cache import cache_dir
from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.engine import Engine, ParseFailure, Tok, load_tables
from miro_gen.idl.keywords import (
    CORBA3_FOLDED,
    RESERVED,
    RESERVED_FOLDED,
    UNSUPPORTED_CONSTRUCTS,
)
from miro_gen.idl.literals import (
    LiteralError,
    decode_char,
    decode_fixed,
    decode_float,
    decode_integer,
    decode_string,
)
from miro_gen.idl.preprocessor import SourceText

GRAMMAR_PATH = Path(__file__).with_name("grammar.lark")

_B = ast.BaseType
T_SHORT, T_LONG, T_LONGLONG = _B("short"), _B("long"), _B("long long")
T_USHORT, T_ULONG, T_ULONGLONG = _B("unsigned short"), _B("unsigned long"), _B("unsigned long long")
T_INT8, T_UINT8 = _B("int8"), _B("uint8")
T_FLOAT, T_DOUBLE, T_LONGDOUBLE = _B("float"), _B("double"), _B("long double")
T_CHAR, T_WCHAR, T_BOOLEAN, T_OCTET = _B("char"), _B("wchar"), _B("boolean"), _B("octet")
T_ANY, T_OBJECT, T_VALUEBASE = _B("any"), _B("Object"), _B("ValueBase")

_Children = list[Any]
Token = Tok


class _AstBuilder:
    """Callbacks, one per grammar rule or alias, building `ast` nodes while parsing."""

    def __init__(self) -> None:
        self.src: SourceText = SourceText("", [], [])
        self.diag = Diagnostics()
        self.named: list[tuple[int, Any]] = []
        self.case_sensitive = False

    def begin(self, src: SourceText, diag: Diagnostics, case_sensitive: bool = False) -> None:
        self.src = src
        self.diag = diag
        self.named = []
        self.case_sensitive = case_sensitive

    # -- helpers ------------------------------------------------------------------------------
    def pos(self, tok: Token) -> SourcePos:
        return self.src.pos_at(tok.start_pos)

    def ident(self, tok: Token) -> str:
        """A declared identifier, checked against the keywords."""
        v = str(tok)
        if v[0] == "_":
            return self._unescaped(tok, v)
        if self.case_sensitive:
            # DDS and ROS 2 files: only the exact spelling of a keyword is one (idlc -f
            # case-sensitive), and a keyword where only a name can stand is that name, as
            # rosidl's parser reads it (`sequence<int32> sequence;` in the Fibonacci action).
            return v
        if v in RESERVED:
            self._keyword_error(tok, v)
            return v
        lv = v.lower()
        kw = RESERVED_FOLDED.get(lv)
        if kw is not None:
            self.diag.error(self.pos(tok), f"identifier '{v}' clashes with keyword '{kw}'")
        else:
            kw3 = CORBA3_FOLDED.get(lv)
            if kw3 is not None:
                self.diag.warning(
                    self.pos(tok), f"identifier '{v}' clashes with CORBA 3 keyword '{kw3}'"
                )
        return v

    def use_ident(self, tok: Token) -> str:
        """An identifier in a scoped name (a use, not a declaration).

        As in omniidl, only declarations are checked against the keywords ignoring case: real
        files escape a declaration (`typedef Object _Factory;`) and use the plain spelling
        (`sequence<Factory>`). `CORBA::Object` and `CORBA::ValueBase` name the built-in types.
        """
        v = str(tok)
        if v[0] == "_":
            return self._unescaped(tok, v)
        if v in RESERVED and tok.type == "IDENT" and not self.case_sensitive:
            self._keyword_error(tok, v)
        return v

    def _unescaped(self, tok: Token, v: str) -> str:
        """An escaped identifier: the underscore is dropped and keywords are allowed."""
        if len(v) == 1 or not v[1].isalpha():
            self.diag.error(self.pos(tok), f"invalid identifier '{v}'")
        return v[1:]

    def _keyword_error(self, tok: Token, v: str) -> None:
        self.diag.error(
            self.pos(tok),
            f"'{v}' is a keyword and cannot be used as a name here "
            f"(write '_{v}' to use it as an identifier)",
        )

    def declared(self, tok: Token, node: Any) -> Any:
        """Record a node named by `tok`, for doc-comment attachment."""
        self.named.append((tok.start_pos or 0, node))
        return node

    def scoped(self, toks: _Children, absolute: bool) -> ast.ScopedName:
        return ast.ScopedName(tuple(self.use_ident(t) for t in toks), absolute, self.pos(toks[0]))

    def instance(self, tok: Token) -> int:
        return self.src.instance_at(tok.start_pos)

    # -- top level ----------------------------------------------------------------------------
    def start(self, c: _Children) -> list[Any]:
        return c

    def annotated(self, c: _Children) -> Any:
        node = c[-1]
        if isinstance(node, (ast.Pragma, ast.TypeIdDcl)):
            self.diag.error(c[0].pos, "annotations cannot be applied here")
        else:
            node.annotations = c[:-1] + node.annotations
        return node

    def pragma(self, c: _Children) -> ast.Pragma:
        tok = c[0]
        return ast.Pragma(str(tok), self.pos(tok), self.instance(tok))

    def module(self, c: _Children) -> ast.Module:
        _kw, name, *defs = c
        node = ast.Module(self.ident(name), self.pos(name), defs, instance=self.instance(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    # -- interfaces ---------------------------------------------------------------------------
    def interface_dcl(self, c: _Children) -> ast.Interface:
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

    def forward_dcl(self, c: _Children) -> ast.Forward:
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

    def interface_inheritance(self, c: _Children) -> list[ast.ScopedName]:
        return [n.name for n in c]

    def op_dcl(self, c: _Children) -> ast.Operation:
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

    def params(self, c: _Children) -> list[ast.Param]:
        return c

    def param_dcl(self, c: _Children) -> ast.Param:
        *anns, mode, typ, name = c
        node = ast.Param(str(mode), typ, self.ident(name), self.pos(name), anns)
        return self.declared(name, node)  # type: ignore[no-any-return]

    def raises_expr(self, c: _Children) -> list[ast.ScopedName]:
        return [n.name for n in c[1:]]

    def context_expr(self, c: _Children) -> list[str]:
        out = []
        for tok in c[1:]:
            out.append(self.string_value(tok))
        return out

    def exception_list(self, c: _Children) -> list[ast.ScopedName]:
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

    def readonly_attr(self, c: _Children) -> ast.AttributeGroup:
        _ro, _kw, typ, name, raises = c
        return self._attr_group(typ, True, [name], raises or [], [])

    def readonly_attrs(self, c: _Children) -> ast.AttributeGroup:
        _ro, _kw, typ, *names = c
        return self._attr_group(typ, True, names, [], [])

    def attr_raises_dcl(self, c: _Children) -> ast.AttributeGroup:
        _kw, typ, name, (get_r, set_r) = c
        return self._attr_group(typ, False, [name], get_r, set_r)

    def attrs(self, c: _Children) -> ast.AttributeGroup:
        _kw, typ, *names = c
        return self._attr_group(typ, False, names, [], [])

    def attr_raises(self, c: _Children) -> tuple[list[ast.ScopedName], list[ast.ScopedName]]:
        if c[0].type == "GETRAISES":
            return c[1], (c[3] if len(c) > 3 and c[3] is not None else [])
        return [], c[1]

    # -- value types --------------------------------------------------------------------------
    def value_forward_dcl(self, c: _Children) -> ast.Forward:
        abstract, _kw, name = c
        node = ast.Forward(
            self.ident(name),
            self.pos(name),
            of="valuetype",
            abstract=abstract is not None,
            instance=self.instance(name),
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def value_box_dcl(self, c: _Children) -> ast.ValueBox:
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

    def value_abs_dcl(self, c: _Children) -> ast.ValueType:
        _abs, _kw, name, inh, *body = c
        return self._value(name, inh, body, abstract=True)

    def value_dcl(self, c: _Children) -> ast.ValueType:
        custom, _kw, name, inh, *body = c
        return self._value(name, inh, body, custom=custom is not None)

    def value_inheritance(self, c: _Children) -> tuple[tuple[bool, list[Any]], list[Any]]:
        bases, supports = c
        return (bases or (False, [])), (supports or [])

    def value_bases(self, c: _Children) -> tuple[bool, list[ast.ScopedName]]:
        trunc, *names = c
        return trunc is not None, [n.name for n in names]

    def value_supports(self, c: _Children) -> list[ast.ScopedName]:
        return [n.name for n in c[1:]]

    def state_member(self, c: _Children) -> ast.StateMemberGroup:
        anns, rest = _split_annotations(c)
        access, typ, *decls = rest
        group = ast.StateMemberGroup(
            str(access) == "public", typ, [d[:3] for d in decls], self.pos(access), anns
        )
        for d in decls:
            self.named.append((d[3], group))
            break
        return group

    def init_dcl(self, c: _Children) -> ast.Factory:
        *anns, _kw, name, params, raises = c
        node = ast.Factory(self.ident(name), self.pos(name), params or [], raises or [], anns)
        return self.declared(name, node)  # type: ignore[no-any-return]

    def init_params(self, c: _Children) -> list[ast.Param]:
        return c

    def init_param(self, c: _Children) -> ast.Param:
        _mode, typ, name = c
        node = ast.Param("in", typ, self.ident(name), self.pos(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    def typeid_dcl(self, c: _Children) -> ast.TypeIdDcl:
        kw, name, value = c
        return ast.TypeIdDcl(False, name.name, self.string_value(value), self.pos(kw))

    def typeprefix_dcl(self, c: _Children) -> ast.TypeIdDcl:
        kw, name, value = c
        return ast.TypeIdDcl(True, name.name, self.string_value(value), self.pos(kw))

    # -- constants and expressions ------------------------------------------------------------
    def const_dcl(self, c: _Children) -> ast.Const:
        _kw, typ, name, expr = c
        node = ast.Const(
            self.ident(name), self.pos(name), type=typ, expr=expr, instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def const_exp(self, c: _Children) -> Any:
        """`a OP b OP c ...` as a flat list -> expression tree, by operator precedence."""
        out: list[Any] = [c[0]]
        ops: list[str] = []

        def reduce() -> None:
            right = out.pop()
            left = out.pop()
            out.append(ast.BinaryOp(ops.pop(), left, right, left.pos))

        for i in range(1, len(c), 2):
            op = str(c[i])
            prec = _PRECEDENCE[op]
            while ops and _PRECEDENCE[ops[-1]] >= prec:
                reduce()
            ops.append(op)
            out.append(c[i + 1])
        while ops:
            reduce()
        return out[0]

    def op_neg(self, c: _Children) -> ast.UnaryOp:
        return ast.UnaryOp("-", c[1], self.pos(c[0]))

    def op_pos(self, c: _Children) -> ast.UnaryOp:
        return ast.UnaryOp("+", c[1], self.pos(c[0]))

    def op_inv(self, c: _Children) -> ast.UnaryOp:
        return ast.UnaryOp("~", c[1], self.pos(c[0]))

    def name_ref(self, c: _Children) -> ast.NameRef:
        return ast.NameRef(c[0].name, c[0].name.pos)

    def _literal(self, tok: Token, kind: str, decode: Any) -> ast.Literal:
        try:
            value = decode(str(tok))
        except LiteralError as e:
            self.diag.error(self.pos(tok), str(e))
            value = decode_placeholder(kind)
        return ast.Literal(kind, value, self.pos(tok))

    def int_lit(self, c: _Children) -> ast.Literal:
        return self._literal(c[0], "int", decode_integer)

    def float_lit(self, c: _Children) -> ast.Literal:
        return self._literal(c[0], "float", decode_float)

    def fixed_lit(self, c: _Children) -> ast.Literal:
        return self._literal(c[0], "fixed", decode_fixed)

    def char_lit(self, c: _Children) -> ast.Literal:
        return self._literal(c[0], "char", decode_char)

    def wchar_lit(self, c: _Children) -> ast.Literal:
        return self._literal(c[0], "wchar", decode_char)

    def string_value(self, tok: Token) -> str:
        try:
            return decode_string(str(tok))
        except LiteralError as e:
            self.diag.error(self.pos(tok), str(e))
            return ""

    def string_lit(self, c: _Children) -> ast.Literal:
        return ast.Literal("string", "".join(self.string_value(t) for t in c), self.pos(c[0]))

    def wstring_lit(self, c: _Children) -> ast.Literal:
        return ast.Literal("wstring", "".join(self.string_value(t) for t in c), self.pos(c[0]))

    def bool_lit(self, c: _Children) -> ast.Literal:
        return ast.Literal("bool", c[0].type == "TRUE", self.pos(c[0]))

    # -- types --------------------------------------------------------------------------------
    def typedef(self, c: _Children) -> ast.TypedefGroup:
        kw, typ, *decls = c
        group = ast.TypedefGroup(
            typ, [d[:3] for d in decls], self.pos(kw), instance=self.instance(kw)
        )
        for d in decls:
            self.named.append((d[3], group))
            break
        return group

    def native(self, c: _Children) -> ast.Native:
        _kw, name = c
        node = ast.Native(self.ident(name), self.pos(name), instance=self.instance(name))
        return self.declared(name, node)  # type: ignore[no-any-return]

    def struct_forward(self, c: _Children) -> ast.Forward:
        _kw, name = c
        node = ast.Forward(
            self.ident(name), self.pos(name), of="struct", instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def union_forward(self, c: _Children) -> ast.Forward:
        _kw, name = c
        node = ast.Forward(
            self.ident(name), self.pos(name), of="union", instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def t_short(self, c: _Children) -> ast.BaseType:
        return T_SHORT

    def t_long(self, c: _Children) -> ast.BaseType:
        return T_LONG

    def t_longlong(self, c: _Children) -> ast.BaseType:
        return T_LONGLONG

    def t_ushort(self, c: _Children) -> ast.BaseType:
        return T_USHORT

    def t_ulong(self, c: _Children) -> ast.BaseType:
        return T_ULONG

    def t_ulonglong(self, c: _Children) -> ast.BaseType:
        return T_ULONGLONG

    def t_int8(self, c: _Children) -> ast.BaseType:
        return T_INT8

    def t_uint8(self, c: _Children) -> ast.BaseType:
        return T_UINT8

    def t_float(self, c: _Children) -> ast.BaseType:
        return T_FLOAT

    def t_double(self, c: _Children) -> ast.BaseType:
        return T_DOUBLE

    def t_longdouble(self, c: _Children) -> ast.BaseType:
        return T_LONGDOUBLE

    def t_char(self, c: _Children) -> ast.BaseType:
        return T_CHAR

    def t_wchar(self, c: _Children) -> ast.BaseType:
        return T_WCHAR

    def t_boolean(self, c: _Children) -> ast.BaseType:
        return T_BOOLEAN

    def t_octet(self, c: _Children) -> ast.BaseType:
        return T_OCTET

    def t_any(self, c: _Children) -> ast.BaseType:
        return T_ANY

    def t_object(self, c: _Children) -> ast.BaseType:
        return T_OBJECT

    def t_valuebase(self, c: _Children) -> ast.BaseType:
        return T_VALUEBASE

    def t_sequence(self, c: _Children) -> ast.SequenceType:
        kw, elem, bound = c
        return ast.SequenceType(elem, bound, self.pos(kw))

    def t_string(self, c: _Children) -> ast.StringType:
        kw, bound = c
        return ast.StringType(False, bound, self.pos(kw))

    def t_wstring(self, c: _Children) -> ast.StringType:
        kw, bound = c
        return ast.StringType(True, bound, self.pos(kw))

    def t_fixed(self, c: _Children) -> ast.FixedType:
        kw, digits, scale = c
        return ast.FixedType(digits, scale, self.pos(kw))

    def t_map(self, c: _Children) -> ast.MapType:
        kw, key, value, bound = c
        return ast.MapType(key, value, bound, self.pos(kw))

    def rel_name(self, c: _Children) -> ast.NamedType:
        return ast.NamedType(self.scoped(c, False))

    def abs_name(self, c: _Children) -> ast.NamedType:
        return ast.NamedType(self.scoped(c, True))

    def declarator(self, c: _Children) -> tuple[str, SourcePos, list[Any], int]:
        name, *dims = c
        return (self.ident(name), self.pos(name), dims, name.start_pos)

    def _members(self, anns: list[Any], typ: Any, decls: list[Any]) -> list[ast.Member]:
        out = []
        for name, pos, dims, start in decls:
            m = ast.Member(name, typ, dims, pos, list(anns))
            self.named.append((start, m))
            out.append(m)
        return out

    def struct_type(self, c: _Children) -> ast.Struct:
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

    def member(self, c: _Children) -> list[ast.Member]:
        anns, rest = _split_annotations(c)
        return self._members(anns, rest[0], rest[1:])

    def union_type(self, c: _Children) -> ast.Union_:
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

    def case(self, c: _Children) -> ast.CaseBranch:
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

    def case_label(self, c: _Children) -> _Label:
        return _Label(c[1] if c[0].type == "CASE" else None, self.pos(c[0]))

    def enum_type(self, c: _Children) -> ast.Enum:
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

    def enumerator(self, c: _Children) -> ast.Enumerator:
        *anns, name = c
        node = ast.Enumerator(
            self.ident(name), self.pos(name), annotations=anns, instance=self.instance(name)
        )
        return self.declared(name, node)  # type: ignore[no-any-return]

    def except_dcl(self, c: _Children) -> ast.Exception_:
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

    # -- annotations --------------------------------------------------------------------------
    def annotation_appl(self, c: _Children) -> ast.Annotation:
        at, name, args = c
        return ast.Annotation(name, args or {}, self.pos(at))

    def annotation_name(self, c: _Children) -> ast.ScopedName:
        # Annotation names may be keywords (`@default`, `@oneway`): no reserved-word check.
        absolute = c[0] is not None
        toks = c[1:]
        return ast.ScopedName(tuple(str(t) for t in toks), absolute, self.pos(toks[0]))

    def ann_single(self, c: _Children) -> dict[str, Any]:
        return {"value": c[0]}

    def ann_named(self, c: _Children) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, expr in c:
            if name in out:
                self.diag.error(expr.pos, f"annotation parameter '{name}' given twice")
            out[name] = expr
        return out

    def ann_param(self, c: _Children) -> tuple[str, Any]:
        return self.ident(c[0]), c[1]

    def annotation_dcl(self, c: _Children) -> ast.AnnotationDecl:
        _kw, name, *body = c
        members = [m for m in body if isinstance(m, tuple)]
        node = ast.AnnotationDecl(
            self.ident(name), self.pos(name), members=members, instance=self.instance(name)
        )
        return node

    def ann_member(self, c: _Children) -> tuple[str, Any, Any]:
        typ, name, _default, expr = c
        return (self.ident(name), typ, expr)

    def ann_enum(self, c: _Children) -> Any:
        return c[0]

    def ann_const(self, c: _Children) -> Any:
        return c[0]

    def ann_typedef(self, c: _Children) -> Any:
        return c[0]

    def typedef_in_ann(self, c: _Children) -> Any:
        return None


_PRECEDENCE = {"|": 1, "^": 2, "&": 3, ">>": 4, "<<": 4, "+": 5, "-": 5, "*": 6, "/": 6, "%": 6}


def _members_and_pragmas(items: _Children) -> tuple[list[ast.Member], list[ast.Pragma]]:
    """A struct or exception body: member groups (one list per line) and `#pragma` lines."""
    members = [m for x in items if not isinstance(x, ast.Pragma) for m in x]
    return members, [x for x in items if isinstance(x, ast.Pragma)]


def _split_annotations(c: _Children) -> tuple[list[Any], list[Any]]:
    i = 0
    while i < len(c) and isinstance(c[i], ast.Annotation):
        i += 1
    return c[:i], c[i:]


class _Label:
    __slots__ = ("expr", "pos")

    def __init__(self, expr: Any, pos: SourcePos) -> None:
        self.expr = expr
        self.pos = pos


def decode_placeholder(kind: str) -> Any:
    return {"int": 0, "float": 0.0, "fixed": 0, "char": "?", "wchar": "?"}.get(kind, "")


# ---- doc comments ---------------------------------------------------------------------------


def _doc_text(comment: str) -> tuple[str, bool] | None:
    """The text of a doc comment and whether it documents the preceding declaration."""
    if comment.startswith("//"):
        if len(comment) < 3 or comment[2] not in "/!" or comment.startswith("////"):
            return None
        body = comment[3:]
        after = body.startswith("<")
        if after:
            body = body[1:]
        return (body[1:] if body.startswith(" ") else body).rstrip(), after
    if len(comment) < 5 or comment[2] not in "*!" or comment.startswith("/**/"):
        return None
    if comment.startswith("/***"):
        return None
    body = comment[3:-2]
    after = body.startswith("<")
    if after:
        body = body[1:]
    lines = body.split("\n")
    cleaned: list[str] = []
    for i, line in enumerate(lines):
        s = line.strip()
        if i > 0 and s.startswith("*"):
            s = s[1:]
            s = s[1:] if s.startswith(" ") else s
        cleaned.append(s.rstrip() if i == 0 else (line if not line.strip().startswith("*") else s))
    # Dedent continuation lines that were not star-prefixed.
    text = "\n".join(x.rstrip() for x in cleaned).strip("\n")
    return _dedent(text), after


def _dedent(text: str) -> str:
    lines = text.split("\n")
    if len(lines) == 1:
        return lines[0].strip()
    first, rest = lines[0].strip(), lines[1:]
    indents = [len(x) - len(x.lstrip()) for x in rest if x.strip()]
    cut = min(indents) if indents else 0
    return "\n".join([first, *(x[cut:] for x in rest)]).strip()


def attach_docs(named: list[tuple[int, Any]], comments: list[tuple[int, str]]) -> None:
    """Give each named node the doc comments between the previous named node and itself."""
    if not comments or not named:
        return
    named.sort(key=lambda item: item[0])
    starts = [n[0] for n in named]
    pending: dict[int, list[tuple[str, bool]]] = {}
    for offset, comment in comments:
        parsed = _doc_text(comment)
        if parsed is None:
            continue
        text, after = parsed
        at = bisect_left(starts, offset)
        idx = at - 1 if after else at
        if 0 <= idx < len(named) and text:
            pending.setdefault(idx, []).append((text, comment.startswith("/*")))
    for idx, texts in pending.items():
        node = named[idx][1]
        if getattr(node, "doc", None) is None:
            node.doc = _join_docs(texts) or None


def _join_docs(texts: list[tuple[str, bool]]) -> str:
    """Consecutive `///` lines form one paragraph; a block comment is a paragraph of its own,
    as Doxygen reads a `//!` brief followed by a `/** */` description."""
    out = ""
    prev_block = False
    for i, (text, block) in enumerate(texts):
        if i:
            out += "\n\n" if block or prev_block else "\n"
        out += text
        prev_block = block
    return out


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
