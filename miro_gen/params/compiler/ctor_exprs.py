"""Expressions and paths of `<constructor>` blocks, translated into Python source.

`ExprTranslator` types every expression (`Val`: its code and a simple kind) and resolves names at
compile time: locals, members of the item and its parents (through the module builder, seen
as `Members`), `<cmath>` constants, IDL constants from the generated IDL modules, other
singletons' values. `constructor.py` adds the statements. Nothing of the input is executed.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Protocol

import lark

from miro_gen.diagnostics import Diagnostics
from miro_gen.params.compiler.cxx_numbers import parse_number
from miro_gen.params.compiler.expressions import CONSTANTS
from miro_gen.params.compiler.model import ItemDecl
from miro_gen.params.compiler.pymodel import PyParamsModule, PyType, idl_constant, pyrepr


class Members(Protocol):
    """What the translator asks the module builder: members through parents, and imports."""

    module: PyParamsModule

    def member(self, item: ItemDecl, name: str) -> tuple[str, PyType] | None:
        """(Python attribute, type) of a member of an item or of its parents."""

    def import_module(self, module: str) -> str:
        """The alias this module imports `module` under."""

    def singleton(self, item: ItemDecl, name: str) -> tuple[str, ItemDecl] | None:
        """(class expression, item) of the parameter class `name` as `item`'s file names it,
        when it has `instance()`."""


_MATH_FUNCTIONS = frozenset(
    [
        "sqrt",
        "sin",
        "cos",
        "tan",
        "asin",
        "acos",
        "atan",
        "atan2",
        "fabs",
        "floor",
        "ceil",
        "pow",
        "exp",
        "log",
        "log10",
        "hypot",
    ]
)
_RUNTIME_STRUCT_FIELDS: dict[str, dict[str, str]] = {
    "_rt.SerialParams": {
        "baudrate": "int",
        "xonlim": "int",
        "xofflim": "int",
        "readmincharacters": "int",
        "readtimeoutmsec": "int",
        "parityenb": "bool",
        "paritymode": "parity",  # a C string in ACE: 0 (NULL) is no parity
        "ctsenb": "bool",
        "rtsenb": "int",
        "xinenb": "bool",
        "xoutenb": "bool",
        "modem": "bool",
        "rcvenb": "bool",
        "dsrenb": "bool",
        "databits": "int",
        "stopbits": "int",
    },
    "_rt.SchedParams": {"policy": "str", "priority": "int", "scope": "str"},
}
_CTYPES = {
    "double": "float",
    "float": "float",
    "bool": "bool",
    "std::string": "str",
    "string": "str",
    "char": "str",
    "CORBA::Double": "float",
    "CORBA::Float": "float",
    "CORBA::Boolean": "bool",
}


class ConstructorError(Exception):
    def __init__(self, meta: Any, message: str) -> None:
        self.line = getattr(meta, "line", 0) or 0
        self.col = getattr(meta, "column", 0) or 0
        super().__init__(message)


@dataclass
class Val:
    """A translated expression or path: Python code, a simple kind ("int", "float", "bool",
    "str", "time", "any", "struct", "vector", "array", ...) and the parameter type of paths."""

    code: str
    kind: str
    type: PyType | None = None
    element: str | None = None  # local arrays: the element kind
    constant: object = None  # a literal's value (enumeration checks)
    struct: str | None = None  # runtime structs: "_rt.SerialParams"


class ExprTranslator:
    """Translates the expressions and paths of one item's blocks; `scopes` hold the locals
    (C++ name -> Val)."""

    def __init__(self, item: ItemDecl, builder: Members, diag: Diagnostics) -> None:
        self.item = item
        self.builder = builder
        self.diag = diag
        self.scopes: list[dict[str, Val]] = [{}]
        self.module = builder.module

    def ctype(self, node: lark.Tree[Any]) -> str:
        words = [str(t) for t in node.children]
        for w in words:
            if w in _CTYPES:
                return _CTYPES[w]
        return "int"

    # -- paths --------------------------------------------------------------------------------

    def lookup_local(self, name: str) -> Val | None:
        for scope in reversed(self.scopes):
            if name in scope:
                return scope[name]
        return None

    def path(self, node: lark.Tree[Any]) -> Val:
        head, *segments = node.children
        name = str(head)
        if name == "this":
            if not segments or segments[0].data != "member":
                raise ConstructorError(node.meta, "this must be followed by ->member")
            name, segments = str(segments[0].children[0]), segments[1:]
            current = self.member_of_item(self.item, name, "self", node.meta)
        else:
            local = self.lookup_local(name)
            if local is not None:
                current = local
            elif "::" not in name and self.builder.member(self.item, name) is not None:
                current = self.member_of_item(self.item, name, "self", node.meta)
            else:
                current = self.constant(name, node.meta)
        for seg in segments:
            if seg.data == "member":
                current = self.member(current, str(seg.children[0]), seg.meta)
            else:
                current = self.index(current, self.expr(seg.children[0]), seg.meta)
        return current

    def member_of_item(self, item: ItemDecl, name: str, code: str, meta: Any) -> Val:
        found = self.builder.member(item, name)
        if found is None:
            raise ConstructorError(meta, f"{item.class_name} has no member {name!r}")
        attr, t = found
        return Val(f"{code}.{attr}", kind_of(t), t, struct=t.annotation)

    def member(self, owner: Val, name: str, meta: Any) -> Val:
        t = owner.type
        if t is not None and t.item is not None:
            return self.member_of_item(t.item, name, owner.code, meta)
        fields = _RUNTIME_STRUCT_FIELDS.get(owner.struct or "")
        if fields is not None and name in fields:
            return Val(f"{owner.code}.{name}", fields[name])
        raise ConstructorError(meta, f"{owner.code.removeprefix('self.')} has no member {name!r}")

    def index(self, owner: Val, idx: Val, meta: Any) -> Val:
        if idx.kind != "int":
            raise ConstructorError(meta, "an index must be an integer")
        if owner.kind == "array" and owner.element is not None:
            return Val(f"{owner.code}[{idx.code}]", owner.element)
        t = owner.type
        if t is None or t.element is None or t.unique:
            raise ConstructorError(meta, f"{owner.code.removeprefix('self.')} is not a vector")
        e = t.element
        return Val(f"{owner.code}[{idx.code}]", kind_of(e), e, struct=e.annotation)

    def constant(self, name: str, meta: Any) -> Val:
        """`M_PI` and the other <cmath>/<climits> constants, or an IDL constant
        (`Miro::RangeSensor::GROUPWISE`), checked by importing its generated module."""
        builtin = CONSTANTS.get(name.lstrip(":").removeprefix("std::"))
        if builtin is not None:
            code = repr(builtin) if math.isfinite(builtin) else f'float("{builtin}")'
            kind = "int" if isinstance(builtin, int) else "float"
            return Val(code, kind, constant=builtin)
        if "::" not in name.lstrip(":"):
            raise ConstructorError(meta, f"unknown name {name!r}")
        found = idl_constant(name)
        if found is None:
            raise ConstructorError(
                meta,
                f"unknown constant {name!r} (IDL constants come from the generated IDL "
                "package; is it generated and importable?)",
            )
        module, attrs, value = found
        kind = {bool: "bool", int: "int", float: "float", str: "str"}[type(value)]
        alias = self.builder.import_module(module)
        return Val(".".join([alias, *attrs]), kind, constant=value)

    def factory(self, t: PyType) -> str:
        """A zero-argument callable making a default element (for resize)."""
        if t.factory is not None:
            return t.factory
        if t.choices:
            return f"lambda: {literal_code(t.choices[0])}"
        ann = t.annotation
        if ann in ("int", "float", "bool", "str"):
            return ann
        if ann == "_dt.timedelta":
            return "_dt.timedelta"
        if ann == "_rt.InetAddr":
            return 'lambda: _rt.InetAddr("localhost", 0)'
        return "list"  # pragma: no cover - every element type is one of the above

    # -- expressions --------------------------------------------------------------------------

    def expr(self, node: Any) -> Val:
        if not isinstance(node, lark.Tree):  # pragma: no cover - the grammar wraps tokens
            raise ConstructorError(None, f"unexpected {node!r}")
        method = getattr(self, f"e_{node.data}", None)
        if method is None:
            raise ConstructorError(node.meta, f"{node.data} expressions are not supported")
        result: Val = method(node)
        return result

    def e_number(self, node: lark.Tree[Any]) -> Val:
        value = parse_number(str(node.children[0]))
        if isinstance(value, float):
            return Val(repr(value), "float", constant=value)
        return Val(str(value), "int", constant=value)

    def e_string(self, node: lark.Tree[Any]) -> Val:
        raw = str(node.children[0])[1:-1]
        escapes = {"n": "\n", "t": "\t", "\\": "\\", '"': '"', "'": "'", "0": "\0"}

        def unescape(m: re.Match[str]) -> str:
            c = m.group(1)
            if c not in escapes:
                raise ConstructorError(node.meta, f"the escape \\{c} is not supported")
            return escapes[c]

        value = re.sub(r"\\(.)", unescape, raw)
        return Val(literal_code(value), "str", constant=value)

    def e_true(self, node: lark.Tree[Any]) -> Val:
        return Val("True", "bool", constant=True)

    def e_false(self, node: lark.Tree[Any]) -> Val:
        return Val("False", "bool", constant=False)

    def e_ref(self, node: lark.Tree[Any]) -> Val:
        v = self.path(node.children[0])
        if v.kind in ("struct", "vector", "array"):
            raise ConstructorError(node.meta, "structures and vectors cannot be used as values")
        return v

    def e_neg(self, node: lark.Tree[Any]) -> Val:
        v = self._number(self.expr(node.children[0]), node.meta, "-")
        constant = -v.constant if isinstance(v.constant, (int, float)) else None
        return Val(f"-{paren(v.code)}", v.kind, constant=constant)

    def e_not_(self, node: lark.Tree[Any]) -> Val:
        v = self.expr(node.children[0])
        return Val(f"not {paren(v.code)}", "bool")

    def e_cast(self, node: lark.Tree[Any]) -> Val:
        kind = self.ctype(node.children[0])
        v = self.expr(node.children[1])
        if kind == "str" or v.kind == "str":
            raise ConstructorError(node.meta, "casts between strings and numbers are not supported")
        return Val(f"{annotation_of(kind)}({bare_arg(v.code)})", kind)

    def e_binop(self, node: lark.Tree[Any]) -> Val:
        left, op_token, right = node.children
        op = str(op_token)
        a, b = self.expr(left), self.expr(right)
        if op == "+" and a.kind == "str" and b.kind == "str":
            return Val(f"({a.code} + {b.code})", "str")
        a = self._number(a, node.meta, op)
        b = self._number(b, node.meta, op)
        kind = "int" if a.kind == b.kind == "int" else "float"
        if op == "/" and kind == "int":
            return Val(f"_rt.cxx_div({a.code}, {b.code})", "int")
        if op == "%":
            if kind != "int":
                raise ConstructorError(node.meta, "% needs integers (use fmod for doubles)")
            return Val(f"_rt.cxx_mod({a.code}, {b.code})", "int")
        return Val(f"({a.code} {op} {b.code})", kind)

    def e_invert(self, node: lark.Tree[Any]) -> Val:
        v = self._integer(self.expr(node.children[0]), node.meta, "~")
        return Val(f"~{paren(v.code)}", "int")

    def e_shift_(self, node: lark.Tree[Any]) -> Val:
        left, op, right = node.children
        a = self._integer(self.expr(left), node.meta, str(op))
        b = self._integer(self.expr(right), node.meta, str(op))
        return Val(f"({a.code} {op} {b.code})", "int")

    def _bits(self, node: lark.Tree[Any], op: str) -> Val:
        a, b = (self._integer(self.expr(c), node.meta, op) for c in node.children)
        return Val(f"({a.code} {op} {b.code})", "int")

    def e_bit_or_(self, node: lark.Tree[Any]) -> Val:
        return self._bits(node, "|")

    def e_bit_xor_(self, node: lark.Tree[Any]) -> Val:
        return self._bits(node, "^")

    def e_bit_and_(self, node: lark.Tree[Any]) -> Val:
        return self._bits(node, "&")

    def _integer(self, v: Val, meta: Any, op: str) -> Val:
        if v.kind not in ("int", "bool"):
            raise ConstructorError(meta, f"{op} needs integers (got a {v.kind})")
        return v

    def e_compare(self, node: lark.Tree[Any]) -> Val:
        left, op, right = node.children
        a, b = self.expr(left), self.expr(right)
        return Val(f"({a.code} {op} {b.code})", "bool")

    def e_and_(self, node: lark.Tree[Any]) -> Val:
        a, b = (self.expr(c) for c in node.children)
        return Val(f"({a.code} and {b.code})", "bool")

    def e_or_(self, node: lark.Tree[Any]) -> Val:
        a, b = (self.expr(c) for c in node.children)
        return Val(f"({a.code} or {b.code})", "bool")

    def e_cond(self, node: lark.Tree[Any]) -> Val:
        c, a, b = (self.expr(n) for n in node.children)
        if a.kind == b.kind:
            kind = a.kind
        elif {a.kind, b.kind} == {"int", "float"}:
            kind = "float"
        else:
            raise ConstructorError(node.meta, f"the branches of ?: differ ({a.kind}, {b.kind})")
        return Val(f"({a.code} if {c.code} else {b.code})", kind)

    def e_instance_member(self, node: lark.Tree[Any]) -> Val:
        """`Miro::RobotParameters::instance()->name`: another singleton's value."""
        path_node, *segments = node.children
        name = str(path_node.children[0]) if len(path_node.children) == 1 else ""
        cls, _, method = name.rpartition("::")
        found = self.builder.singleton(self.item, cls) if method == "instance" else None
        if found is None:
            raise ConstructorError(
                node.meta, f"{source_text(path_node)}() is not the instance() of a parameter class"
            )
        code, item = found
        first, *rest = segments
        if first.data != "member":
            raise ConstructorError(node.meta, f"{name}() is not an array")
        current = self.member_of_item(item, str(first.children[0]), f"{code}.instance()", node.meta)
        for seg in rest:
            if seg.data == "member":
                current = self.member(current, str(seg.children[0]), seg.meta)
            else:
                current = self.index(current, self.expr(seg.children[0]), seg.meta)
        if current.kind in ("struct", "vector", "set", "array"):
            raise ConstructorError(node.meta, "structures and vectors cannot be used as values")
        return current

    def e_call(self, node: lark.Tree[Any]) -> Val:
        path_node = node.children[0]
        args = [self.expr(a) for a in node.children[1:] if isinstance(a, lark.Tree)]
        if len(path_node.children) != 1:
            raise ConstructorError(
                node.meta, f"calling {source_text(path_node)}() is not supported"
            )
        name = str(path_node.children[0]).lstrip(":")
        base = name.rsplit("::", 1)[-1]
        if name in ("Miro::deg2Rad", "deg2Rad", "Miro::rad2Deg", "rad2Deg"):
            (arg,) = self._args(args, 1, name, node.meta)
            fn = "_rt.deg2rad" if base == "deg2Rad" else "_rt.rad2deg"
            return Val(f"{fn}({bare_arg(self._number(arg, node.meta, name).code)})", "float")
        if base in _MATH_FUNCTIONS and name in (base, f"std::{base}"):
            self.module.uses_math = True
            codes = [self._number(a, node.meta, name).code for a in args]
            return Val(f"_math.{base}({', '.join(map(bare_arg, codes))})", "float")
        if name in ("abs", "std::abs"):
            (arg,) = self._args(args, 1, name, node.meta)
            return Val(f"abs({bare_arg(arg.code)})", self._number(arg, node.meta, name).kind)
        if name == "ACE_Time_Value":
            if not 1 <= len(args) <= 2 or any(a.kind != "int" for a in args):
                raise ConstructorError(node.meta, "ACE_Time_Value(sec, usec) takes integers")
            self.module.uses_datetime = True
            return Val(f"_rt.time_value({', '.join(bare_arg(a.code) for a in args)})", "time")
        if name in ("std::string", "string"):
            (arg,) = self._args(args, 1, name, node.meta)
            if arg.kind != "str":
                raise ConstructorError(node.meta, "std::string() takes a string")
            return arg
        raise ConstructorError(node.meta, f"the function {name}() is not supported")

    def _args(self, args: list[Val], n: int, name: str, meta: Any) -> list[Val]:
        if len(args) != n:
            raise ConstructorError(meta, f"{name}() takes {n} argument(s), not {len(args)}")
        return args

    def _number(self, v: Val, meta: Any, op: str) -> Val:
        if v.kind not in ("int", "float"):
            raise ConstructorError(meta, f"{op} needs numbers (got a {v.kind})")
        return v

    def convert(
        self, value: Val, kind: str, meta: Any, what: str, target: PyType | None = None
    ) -> str:
        """The code of `value` stored into a place of `kind`; an error when C++ would refuse
        or would silently lose information (a double into an int)."""
        if target is not None and target.choices:
            if value.kind != "str":
                raise ConstructorError(meta, f"{what} takes one of {', '.join(target.choices)}")
            if value.constant is not None and value.constant not in target.choices:
                raise ConstructorError(
                    meta, f"{value.constant!r} is not one of {', '.join(target.choices)}"
                )
            if value.constant is None:
                raise ConstructorError(meta, f"{what} takes a literal string")
            return value.code
        if kind == value.kind:
            return value.code
        if kind == "parity":
            if value.kind == "str":
                return value.code
            if value.kind == "int" and value.constant == 0:
                return '"none"'
        if kind == "float" and value.kind == "int":
            return value.code
        if kind == "bool" and value.kind == "int":
            return f"bool({bare_arg(value.code)})"
        if kind in ("struct", "vector", "set"):
            raise ConstructorError(
                meta, f"assigning a whole structure or vector to {what} is not supported"
            )
        raise ConstructorError(meta, f"cannot store a {value.kind} in {what} (a {kind})")


def kind_of(t: PyType) -> str:
    if t.element is not None:
        return "set" if t.unique else "vector"
    if t.item is not None or t.annotation in _RUNTIME_STRUCT_FIELDS:
        return "struct"
    if t.choices:
        return "str"
    return {
        "int": "int",
        "float": "float",
        "bool": "bool",
        "str": "str",
        "_dt.timedelta": "time",
        "_rt.InetAddr": "address",
    }.get(t.annotation, "other")


def annotation_of(kind: str) -> str:
    return {"int": "int", "float": "float", "bool": "bool", "str": "str"}.get(kind, "object")


def literal_code(value: str) -> str:
    return pyrepr(value)


def bare_arg(code: str) -> str:
    """An argument without the parentheses around all of it (ruff's UP034)."""
    if code.startswith("(") and code.endswith(")"):
        depth = 0
        for i, c in enumerate(code):
            depth += {"(": 1, ")": -1}.get(c, 0)
            if depth == 0 and i < len(code) - 1:
                return code  # `(a) + (b)`: the first parenthesis closes early
        return code[1:-1]
    return code


def paren(code: str) -> str:
    return code if re.fullmatch(r"[\w.]+|\(.*\)", code) else f"({code})"


def source_text(node: lark.Tree[Any]) -> str:
    """A path as the C++ source spelled it (for messages)."""
    out = str(node.children[0])
    for seg in node.children[1:]:
        out += f".{seg.children[0]}" if seg.data == "member" else "[...]"
    return out
