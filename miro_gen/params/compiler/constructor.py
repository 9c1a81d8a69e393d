"""`<constructor>` blocks: C++-like default-building statements compiled into Python.

The statements are parsed with `constructor.lark` and translated, statement by statement, into
Python source that the template puts into the class's `_construct` method: the input text is
never executed. Names are resolved at compile time (members of the item and its parents, local
constants, loop variables, `M_PI`, IDL constants such as `Miro::RangeSensor::GROUPWISE`), paths
are typed through the parameter classes and IDL structs, and anything outside the subset is an
error naming the file, the line and the construct.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Protocol

import lark

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.params.compiler.expressions import CONSTANTS, parse_number, parser
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


def compile_constructor(item: ItemDecl, builder: Members, diag: Diagnostics) -> list[str]:
    """The Python statements of an item's `<constructor>` blocks (errors in `diag`): one
    C++ constructor body, so a block sees the locals of the blocks before it."""
    translator: Translator | None = None
    out: list[str] = []
    for block in item.constructors:
        try:
            tree = parser().parse(block.text, start="start")
            if translator is None:
                translator = Translator(item, builder, block.pos, diag)
            translator.start = block.pos
            out += translator.statements(tree.children, 0)
        except lark.exceptions.UnexpectedInput as e:
            got = _describe(e)
            diag.error(_pos(block.pos, e.line, e.column), f"constructor: unexpected {got}")
        except RecursionError:
            diag.error(block.pos, "constructor: the block is nested too deeply")
    return out


def _describe(e: lark.exceptions.UnexpectedInput) -> str:
    token = getattr(e, "token", None)
    if token is not None:
        return "end of block" if token.type == "$END" else repr(str(token))
    char = getattr(e, "char", None)
    return repr(char) if char else "input"


def _pos(start: SourcePos, line: int, col: int) -> SourcePos:
    """Lark's position inside the block -> the file's: the block starts on the tag's line."""
    line = max(line, 1)
    return SourcePos(start.path, start.line + line - 1, col if line > 1 else 0)


class Translator:
    """Translates the statements of one block; `scopes` hold locals (C++ name -> Val)."""

    def __init__(
        self, item: ItemDecl, builder: Members, start: SourcePos, diag: Diagnostics
    ) -> None:
        self.item = item
        self.builder = builder
        self.start = start
        self.diag = diag
        self.scopes: list[dict[str, Val]] = [{}]
        self.module = builder.module

    # -- statements ---------------------------------------------------------------------------

    def statements(self, nodes: list[Any], depth: int) -> list[str]:
        out: list[str] = []
        for node in nodes:
            if not isinstance(node, lark.Tree):
                continue
            try:
                out += self.statement(node, depth)
            except ConstructorError as e:
                self.diag.error(_pos(self.start, e.line, e.col), f"constructor: {e}")
        return out

    def statement(self, node: lark.Tree[Any], depth: int) -> list[str]:
        pad = "    " * depth
        kind = node.data
        if kind == "empty":
            return []
        if kind == "block":
            self.scopes.append({})
            try:
                return self.statements(node.children, depth)
            finally:
                self.scopes.pop()
        if kind == "array_decl":
            return [pad + line for line in self.array_decl(node)]
        if kind == "var_decl":
            return [pad + line for line in self.var_decl(node)]
        if kind == "assign":
            return [pad + self.assign(node)]
        if kind == "call_stmt":
            return [pad + self.call_stmt(node)]
        if kind == "incdec":
            return [pad + self.incdec(node)]
        if kind == "for_stmt":
            return self.for_stmt(node, depth)
        if kind == "if_stmt":
            return self.if_stmt(node, depth)
        raise ConstructorError(node.meta, f"{kind} statements are not supported")

    def _local_name(self, name: str, meta: Any) -> str:
        if "::" in name:
            raise ConstructorError(meta, f"a local variable cannot be called {name!r}")
        return f"_l_{name}"

    def array_decl(self, node: lark.Tree[Any]) -> list[str]:
        children = [c for c in node.children if c is not None]
        ctype = next(c for c in children if isinstance(c, lark.Tree) and c.data == "ctype")
        rest = children[children.index(ctype) + 1 :]
        name = str(rest[0])
        size_tokens = [c for c in rest[1:] if isinstance(c, lark.Token) and c.type == "NUMBER"]
        values = [self.expr(c) for c in rest[1:] if isinstance(c, lark.Tree)]
        kind = self.ctype(ctype)
        codes = [self.convert(v, kind, node.meta, f"an element of {name}") for v in values]
        if size_tokens:
            size = parse_number(str(size_tokens[0]))
            if not isinstance(size, int) or size < len(values):
                raise ConstructorError(
                    node.meta, f"{name}[{size_tokens[0]}] is given {len(values)} values"
                )
            if size > 100_000:
                raise ConstructorError(node.meta, f"{name}[{size}] is too large")
            # C++ value-initialises the elements not given
            zero = {"int": "0", "float": "0.0", "bool": "False", "str": '""'}.get(kind, "0")
            codes += [zero] * (size - len(codes))
        local = self._local_name(name, node.meta)
        self.scopes[-1][name] = Val(local, "array", element=kind)
        if not codes:
            return [f"{local}: tuple[{_annotation(kind)}, ...] = ()"]
        body = ", ".join(codes) + ("," if len(codes) == 1 else "")
        return [f"{local} = ({body})"]

    def var_decl(self, node: lark.Tree[Any]) -> list[str]:
        children = [c for c in node.children if c is not None]
        ctype = next(c for c in children if isinstance(c, lark.Tree) and c.data == "ctype")
        name_token, value_node = children[children.index(ctype) + 1 :]
        kind = self.ctype(ctype)
        value = self.expr(value_node)
        code = self.convert(value, kind, node.meta, str(name_token))
        local = self._local_name(str(name_token), node.meta)
        self.scopes[-1][str(name_token)] = Val(local, kind)
        return [f"{local}: {_annotation(kind)} = {code}"]

    def ctype(self, node: lark.Tree[Any]) -> str:
        words = [str(t) for t in node.children]
        for w in words:
            if w in _CTYPES:
                return _CTYPES[w]
        return "int"

    def assign(self, node: lark.Tree[Any]) -> str:
        path_node, op, value_node = node.children
        target = self.path(path_node)
        value = self.expr(value_node)
        op = str(op)
        if target.kind == "array":
            raise ConstructorError(node.meta, "a local array cannot be assigned to")
        if target.type is None and target.kind not in ("int", "float", "bool", "str", "parity"):
            raise ConstructorError(node.meta, f"cannot assign to {_src(path_node)}")
        if op == "=":
            code = self.convert(value, target.kind, node.meta, _src(path_node), target.type)
            return f"{target.code} = {code}"
        if target.kind not in ("int", "float") and not (target.kind == "str" and op == "+="):
            raise ConstructorError(node.meta, f"{op} needs a number (got {_src(path_node)})")
        if op == "/=" and target.kind == "int":
            return f"{target.code} = _rt.cxx_div({target.code}, {value.code})"
        rhs = self.convert(value, target.kind, node.meta, _src(path_node), target.type)
        return f"{target.code} {op} {rhs}"

    def incdec(self, node: lark.Tree[Any]) -> str:
        tokens = [c for c in node.children if isinstance(c, lark.Token)]
        path_node = next(c for c in node.children if isinstance(c, lark.Tree))
        target = self.path(path_node)
        if target.kind != "int":
            raise ConstructorError(node.meta, f"{tokens[0]} needs an integer")
        return f"{target.code} {'+' if str(tokens[0]) == '++' else '-'}= 1"

    def call_stmt(self, node: lark.Tree[Any]) -> str:
        path_node = node.children[0]
        args = [self.expr(a) for a in node.children[1:] if isinstance(a, lark.Tree)]
        segments = path_node.children
        if len(segments) < 2 or not (
            isinstance(segments[-1], lark.Tree) and segments[-1].data == "member"
        ):
            raise ConstructorError(node.meta, f"calling {_src(path_node)}() is not supported")
        method = str(segments[-1].children[0])
        owner_node = lark.Tree("path", segments[:-1], path_node.meta)
        owner = self.path(owner_node)
        t = owner.type
        if t is None or t.element is None:
            raise ConstructorError(
                node.meta, f"{_src(owner_node)}.{method}() needs a vector or set member"
            )
        if method in ("length", "resize") and not t.unique:
            if len(args) != 1 or args[0].kind != "int":
                raise ConstructorError(node.meta, f"{method}() takes one integer")
            return f"_rt.resize({owner.code}, {args[0].code}, {self.factory(t.element)})"
        if method in ("push_back", "insert") and len(args) == 1:
            code = self.convert(args[0], _kind(t.element), node.meta, method, t.element)
            return f"{owner.code}.{'add' if t.unique else 'append'}({_arg(code)})"
        if method == "clear" and not args:
            return f"{owner.code}.clear()"
        raise ConstructorError(node.meta, f"{method}() is not supported on {t.spelling}")

    def for_stmt(self, node: lark.Tree[Any], depth: int) -> list[str]:
        init, var, cmp, bound_node, step, body = node.children
        init_children = [c for c in init.children if not isinstance(c, lark.Tree)]
        name, start_node = str(init_children[0]), init.children[-1]
        if str(var) != name:
            raise ConstructorError(node.meta, f"the loop tests {var}, not its variable {name}")
        start = self.expr(start_node)
        bound = self.expr(bound_node)
        step_value = self.step(step, name)
        for v, what in ((start, "start"), (bound, "bound")):
            if v.kind != "int":
                raise ConstructorError(node.meta, f"the loop's {what} must be an integer")
        cmp = str(cmp)
        down = step_value.startswith("-")
        if (cmp in ("<", "<=") and down) or (cmp in (">", ">=") and not down):
            raise ConstructorError(node.meta, "the loop never ends")
        end = {
            "<": bound.code,
            "<=": f"{bound.code} + 1",
            ">": bound.code,
            ">=": f"{bound.code} - 1",
        }.get(cmp)
        if end is None:
            raise ConstructorError(node.meta, f"a loop condition with {cmp} is not supported")
        local = self._local_name(name, node.meta)
        step_arg = "" if step_value == "1" else f", {step_value}"
        self.scopes.append({name: Val(local, "int")})
        try:
            inner = self.statements([body], depth + 1)
        finally:
            self.scopes.pop()
        pad = "    " * depth
        return [f"{pad}for {local} in range({start.code}, {end}{step_arg}):"] + (
            inner or [pad + "    pass"]
        )

    def if_stmt(self, node: lark.Tree[Any], depth: int) -> list[str]:
        cond_node, then, *rest = [c for c in node.children if c is not None]
        cond = self.expr(cond_node)
        if cond.kind not in ("bool", "int", "float"):
            raise ConstructorError(node.meta, f"an if needs a condition (got a {cond.kind})")
        pad = "    " * depth
        out = [f"{pad}if {cond.code}:"] + (self.statements([then], depth + 1) or [pad + "    pass"])
        if rest:
            out += [f"{pad}else:"] + (self.statements(rest, depth + 1) or [pad + "    pass"])
        return out

    def step(self, node: lark.Tree[Any], name: str) -> str:
        tokens = [c for c in node.children if isinstance(c, lark.Token)]
        names = [str(t) for t in tokens if t.type == "NAME"]
        if names != [name]:
            raise ConstructorError(node.meta, f"the loop must step its variable {name}")
        if node.data == "step_incdec":
            op = next(str(t) for t in tokens if t.type == "INCDEC")
            return "1" if op == "++" else "-1"
        op = next(str(t) for t in tokens if t.type == "STEP_ASSIGN")
        amount = self.expr(node.children[-1])
        if amount.constant is None or amount.kind != "int" or amount.constant == 0:
            raise ConstructorError(node.meta, "a loop steps by a non-zero integer constant")
        return amount.code if op == "+=" else f"-{amount.code}"

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
        return Val(f"{code}.{attr}", _kind(t), t, struct=t.annotation)

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
        return Val(f"{owner.code}[{idx.code}]", _kind(e), e, struct=e.annotation)

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
            return f"lambda: {_literal(t.choices[0])}"
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
        return Val(_literal(value), "str", constant=value)

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
        return Val(f"-{_paren(v.code)}", v.kind, constant=constant)

    def e_not_(self, node: lark.Tree[Any]) -> Val:
        v = self.expr(node.children[0])
        return Val(f"not {_paren(v.code)}", "bool")

    def e_cast(self, node: lark.Tree[Any]) -> Val:
        kind = self.ctype(node.children[0])
        v = self.expr(node.children[1])
        if kind == "str" or v.kind == "str":
            raise ConstructorError(node.meta, "casts between strings and numbers are not supported")
        return Val(f"{_annotation(kind)}({_arg(v.code)})", kind)

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
        return Val(f"~{_paren(v.code)}", "int")

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
                node.meta, f"{_src(path_node)}() is not the instance() of a parameter class"
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
            raise ConstructorError(node.meta, f"calling {_src(path_node)}() is not supported")
        name = str(path_node.children[0]).lstrip(":")
        base = name.rsplit("::", 1)[-1]
        if name in ("Miro::deg2Rad", "deg2Rad", "Miro::rad2Deg", "rad2Deg"):
            (arg,) = self._args(args, 1, name, node.meta)
            fn = "_rt.deg2rad" if base == "deg2Rad" else "_rt.rad2deg"
            return Val(f"{fn}({_arg(self._number(arg, node.meta, name).code)})", "float")
        if base in _MATH_FUNCTIONS and name in (base, f"std::{base}"):
            self.module.uses_math = True
            codes = [self._number(a, node.meta, name).code for a in args]
            return Val(f"_math.{base}({', '.join(map(_arg, codes))})", "float")
        if name in ("abs", "std::abs"):
            (arg,) = self._args(args, 1, name, node.meta)
            return Val(f"abs({_arg(arg.code)})", self._number(arg, node.meta, name).kind)
        if name == "ACE_Time_Value":
            if not 1 <= len(args) <= 2 or any(a.kind != "int" for a in args):
                raise ConstructorError(node.meta, "ACE_Time_Value(sec, usec) takes integers")
            self.module.uses_datetime = True
            return Val(f"_rt.time_value({', '.join(_arg(a.code) for a in args)})", "time")
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
            return f"bool({_arg(value.code)})"
        if kind in ("struct", "vector", "set"):
            raise ConstructorError(
                meta, f"assigning a whole structure or vector to {what} is not supported"
            )
        raise ConstructorError(meta, f"cannot store a {value.kind} in {what} (a {kind})")


def _kind(t: PyType) -> str:
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


def _annotation(kind: str) -> str:
    return {"int": "int", "float": "float", "bool": "bool", "str": "str"}.get(kind, "object")


def _literal(value: str) -> str:
    return pyrepr(value)


def _arg(code: str) -> str:
    """An argument without the parentheses around all of it (ruff's UP034)."""
    if code.startswith("(") and code.endswith(")"):
        depth = 0
        for i, c in enumerate(code):
            depth += {"(": 1, ")": -1}.get(c, 0)
            if depth == 0 and i < len(code) - 1:
                return code  # `(a) + (b)`: the first parenthesis closes early
        return code[1:-1]
    return code


def _paren(code: str) -> str:
    return code if re.fullmatch(r"[\w.]+|\(.*\)", code) else f"({code})"


def _src(node: lark.Tree[Any]) -> str:
    """A path as the C++ source spelled it (for messages)."""
    out = str(node.children[0])
    for seg in node.children[1:]:
        out += f".{seg.children[0]}" if seg.data == "member" else "[...]"
    return out
