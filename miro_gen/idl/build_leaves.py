"""The parser's callbacks for the leaves of the syntax: identifiers (checked against the
keywords), scoped names, constant expressions and literals, type specs, and annotations (their
applications and IDL 4 declarations). `LeafBuilder` is the base of the parser's AST builder
(miro_gen.idl.parser), which adds the declarations; the engine calls both by rule name.
"""

from __future__ import annotations

from typing import Any

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.engine import Tok
from miro_gen.idl.keywords import CORBA3_FOLDED, RESERVED, RESERVED_FOLDED
from miro_gen.idl.literals import (
    LiteralError,
    decode_char,
    decode_fixed,
    decode_float,
    decode_integer,
    decode_string,
)
from miro_gen.idl.source_text import SourceText

_B = ast.BaseType
T_SHORT, T_LONG, T_LONGLONG = _B("short"), _B("long"), _B("long long")
T_USHORT, T_ULONG, T_ULONGLONG = _B("unsigned short"), _B("unsigned long"), _B("unsigned long long")
T_INT8, T_UINT8 = _B("int8"), _B("uint8")
T_FLOAT, T_DOUBLE, T_LONGDOUBLE = _B("float"), _B("double"), _B("long double")
T_CHAR, T_WCHAR, T_BOOLEAN, T_OCTET = _B("char"), _B("wchar"), _B("boolean"), _B("octet")
T_ANY, T_OBJECT, T_VALUEBASE = _B("any"), _B("Object"), _B("ValueBase")

Children = list[Any]
Token = Tok
_PRECEDENCE = {"|": 1, "^": 2, "&": 3, ">>": 4, "<<": 4, "+": 5, "-": 5, "*": 6, "/": 6, "%": 6}


def decode_placeholder(kind: str) -> Any:
    return {"int": 0, "float": 0.0, "fixed": 0, "char": "?", "wchar": "?"}.get(kind, "")


class LeafBuilder:
    """Callbacks for identifiers, names, expressions, literals, types and annotations, with the
    state of one parse (its text, diagnostics, the named nodes for doc comments)."""

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

    def scoped(self, toks: Children, absolute: bool) -> ast.ScopedName:
        return ast.ScopedName(tuple(self.use_ident(t) for t in toks), absolute, self.pos(toks[0]))

    def instance(self, tok: Token) -> int:
        return self.src.instance_at(tok.start_pos)

    def const_exp(self, c: Children) -> Any:
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

    def op_neg(self, c: Children) -> ast.UnaryOp:
        return ast.UnaryOp("-", c[1], self.pos(c[0]))

    def op_pos(self, c: Children) -> ast.UnaryOp:
        return ast.UnaryOp("+", c[1], self.pos(c[0]))

    def op_inv(self, c: Children) -> ast.UnaryOp:
        return ast.UnaryOp("~", c[1], self.pos(c[0]))

    def name_ref(self, c: Children) -> ast.NameRef:
        return ast.NameRef(c[0].name, c[0].name.pos)

    def _literal(self, tok: Token, kind: str, decode: Any) -> ast.Literal:
        try:
            value = decode(str(tok))
        except LiteralError as e:
            self.diag.error(self.pos(tok), str(e))
            value = decode_placeholder(kind)
        return ast.Literal(kind, value, self.pos(tok))

    def int_lit(self, c: Children) -> ast.Literal:
        return self._literal(c[0], "int", decode_integer)

    def float_lit(self, c: Children) -> ast.Literal:
        return self._literal(c[0], "float", decode_float)

    def fixed_lit(self, c: Children) -> ast.Literal:
        return self._literal(c[0], "fixed", decode_fixed)

    def char_lit(self, c: Children) -> ast.Literal:
        return self._literal(c[0], "char", decode_char)

    def wchar_lit(self, c: Children) -> ast.Literal:
        return self._literal(c[0], "wchar", decode_char)

    def string_value(self, tok: Token) -> str:
        try:
            return decode_string(str(tok), latin1=not self.case_sensitive)
        except LiteralError as e:
            self.diag.error(self.pos(tok), str(e))
            return ""

    def string_lit(self, c: Children) -> ast.Literal:
        return ast.Literal("string", "".join(self.string_value(t) for t in c), self.pos(c[0]))

    def wstring_lit(self, c: Children) -> ast.Literal:
        return ast.Literal("wstring", "".join(self.string_value(t) for t in c), self.pos(c[0]))

    def bool_lit(self, c: Children) -> ast.Literal:
        return ast.Literal("bool", c[0].type == "TRUE", self.pos(c[0]))

    def t_short(self, c: Children) -> ast.BaseType:
        return T_SHORT

    def t_long(self, c: Children) -> ast.BaseType:
        return T_LONG

    def t_longlong(self, c: Children) -> ast.BaseType:
        return T_LONGLONG

    def t_ushort(self, c: Children) -> ast.BaseType:
        return T_USHORT

    def t_ulong(self, c: Children) -> ast.BaseType:
        return T_ULONG

    def t_ulonglong(self, c: Children) -> ast.BaseType:
        return T_ULONGLONG

    def t_int8(self, c: Children) -> ast.BaseType:
        return T_INT8

    def t_uint8(self, c: Children) -> ast.BaseType:
        return T_UINT8

    def t_float(self, c: Children) -> ast.BaseType:
        return T_FLOAT

    def t_double(self, c: Children) -> ast.BaseType:
        return T_DOUBLE

    def t_longdouble(self, c: Children) -> ast.BaseType:
        return T_LONGDOUBLE

    def t_char(self, c: Children) -> ast.BaseType:
        return T_CHAR

    def t_wchar(self, c: Children) -> ast.BaseType:
        return T_WCHAR

    def t_boolean(self, c: Children) -> ast.BaseType:
        return T_BOOLEAN

    def t_octet(self, c: Children) -> ast.BaseType:
        return T_OCTET

    def t_any(self, c: Children) -> ast.BaseType:
        return T_ANY

    def t_object(self, c: Children) -> ast.BaseType:
        return T_OBJECT

    def t_valuebase(self, c: Children) -> ast.BaseType:
        return T_VALUEBASE

    def t_sequence(self, c: Children) -> ast.SequenceType:
        kw, elem, bound = c
        return ast.SequenceType(elem, bound, self.pos(kw))

    def t_string(self, c: Children) -> ast.StringType:
        kw, bound = c
        return ast.StringType(False, bound, self.pos(kw))

    def t_wstring(self, c: Children) -> ast.StringType:
        kw, bound = c
        return ast.StringType(True, bound, self.pos(kw))

    def t_fixed(self, c: Children) -> ast.FixedType:
        kw, digits, scale = c
        return ast.FixedType(digits, scale, self.pos(kw))

    def t_map(self, c: Children) -> ast.MapType:
        kw, key, value, bound = c
        return ast.MapType(key, value, bound, self.pos(kw))

    def rel_name(self, c: Children) -> ast.NamedType:
        return ast.NamedType(self.scoped(c, False))

    def abs_name(self, c: Children) -> ast.NamedType:
        return ast.NamedType(self.scoped(c, True))

    # -- annotations --------------------------------------------------------------------------
    def annotation_appl(self, c: Children) -> ast.Annotation:
        at, name, args = c
        return ast.Annotation(name, args or {}, self.pos(at))

    def annotation_name(self, c: Children) -> ast.ScopedName:
        # Annotation names may be keywords (`@default`, `@oneway`): no reserved-word check.
        absolute = c[0] is not None
        toks = c[1:]
        return ast.ScopedName(tuple(str(t) for t in toks), absolute, self.pos(toks[0]))

    def ann_single(self, c: Children) -> dict[str, Any]:
        return {"value": c[0]}

    def ann_named(self, c: Children) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, expr in c:
            if name in out:
                self.diag.error(expr.pos, f"annotation parameter '{name}' given twice")
            out[name] = expr
        return out

    def ann_param(self, c: Children) -> tuple[str, Any]:
        return self.ident(c[0]), c[1]

    def annotation_dcl(self, c: Children) -> ast.AnnotationDecl:
        _kw, name, *body = c
        members = [m for m in body if isinstance(m, tuple)]
        node = ast.AnnotationDecl(
            self.ident(name), self.pos(name), members=members, instance=self.instance(name)
        )
        return node

    def ann_member(self, c: Children) -> tuple[str, Any, Any]:
        typ, name, _default, expr = c
        return (self.ident(name), typ, expr)

    def ann_enum(self, c: Children) -> Any:
        return c[0]

    def ann_const(self, c: Children) -> Any:
        return c[0]

    def ann_typedef(self, c: Children) -> Any:
        return c[0]

    def typedef_in_ann(self, c: Children) -> Any:
        return None
