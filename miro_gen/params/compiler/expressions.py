"""C++ constant expressions: what makeParams files write in `default=`.

makeParams pasted `default="..."` into the generated C++ constructor (`member(default)`), so real
files hold C++ expressions: `150*1024*1024`, `M_PI/2`, `(double)1/3`, `0x10`, `INFINITY`, the
arguments of a constructor (`"0, 100000"` for an `ACE_Time_Value`, `"ACE_SCHED_FIFO, 50"` for
`ACE_Sched_Params`). They are parsed with the `<constructor>` grammar (`constructor.lark`, rule
`default_args`) and evaluated here, with C++'s arithmetic (integer division truncates, `%` takes
the dividend's sign, casts truncate and wrap), never with `eval`. Anything outside the subset
raises `ExprError` naming the construct.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import lark

from miro_gen.params.compiler.cxx_numbers import (
    ExprError,
    ExprValueError,
    Float32,
    cast_int,
    common_type,
    floating_result,
    int_type,
    parse_number,
    typed,
)
from miro_gen.params.compiler.nesting import MAX_NESTING, too_deep

__all__ = [
    "ExprError",
    "Symbol",
    "TimeValue",
    "Value",
    "evaluate_args",
    "parser",
    "to_bool",
    "to_float",
    "to_int",
]


@dataclass(frozen=True)
class TimeValue:
    """`ACE_Time_Value(sec, usec)`."""

    sec: int
    usec: int


@dataclass(frozen=True)
class Symbol:
    """A named constant that is not a number: `ACE_SCHED_FIFO`, `ACE_SCOPE_THREAD`."""

    name: str


Value = bool | int | float | str | TimeValue | Symbol

# <cmath>'s, <climits>' and <cfloat>'s constants (the macros Miro's files used), LP64 sizes
CONSTANTS: dict[str, int | float] = {
    "M_PI": math.pi,
    "M_PI_2": math.pi / 2,
    "M_PI_4": math.pi / 4,
    "M_1_PI": 1 / math.pi,
    "M_2_PI": 2 / math.pi,
    "M_2_SQRTPI": 2 / math.sqrt(math.pi),
    "M_E": math.e,
    "M_LOG2E": math.log2(math.e),
    "M_LOG10E": math.log10(math.e),
    "M_LN2": math.log(2),
    "M_LN10": math.log(10),
    "M_SQRT2": math.sqrt(2),
    "M_SQRT1_2": math.sqrt(0.5),
    "INFINITY": math.inf,
    "HUGE_VAL": math.inf,
    "NAN": math.nan,
    "DBL_MAX": 1.7976931348623157e308,
    "DBL_MIN": 2.2250738585072014e-308,
    "DBL_EPSILON": 2.220446049250313e-16,
    "FLT_MAX": 3.4028234663852886e38,
    "FLT_MIN": 1.1754943508222875e-38,
    "FLT_EPSILON": 1.1920928955078125e-07,
    "CHAR_BIT": 8,
    "SCHAR_MIN": -(2**7),
    "SCHAR_MAX": 2**7 - 1,
    "UCHAR_MAX": 2**8 - 1,
    "SHRT_MIN": -(2**15),
    "SHRT_MAX": 2**15 - 1,
    "USHRT_MAX": 2**16 - 1,
    "INT_MIN": -(2**31),
    "INT_MAX": 2**31 - 1,
    "UINT_MAX": 2**32 - 1,
    "LONG_MIN": -(2**63),
    "LONG_MAX": 2**63 - 1,
    "ULONG_MAX": 2**64 - 1,
    "LLONG_MIN": -(2**63),
    "LLONG_MAX": 2**63 - 1,
    "ULLONG_MAX": 2**64 - 1,
}
SYMBOLS = frozenset(
    [
        "ACE_SCHED_OTHER",
        "ACE_SCHED_FIFO",
        "ACE_SCHED_RR",
        "ACE_SCOPE_THREAD",
        "ACE_SCOPE_PROCESS",
        "ACE_SCOPE_LWP",
    ]
)
_TIME_CONSTANTS = {"ACE_Time_Value::zero": TimeValue(0, 0)}

_MATH_1: dict[str, Callable[[float], float]] = {
    "sqrt": math.sqrt,
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "asin": math.asin,
    "acos": math.acos,
    "atan": math.atan,
    "sinh": math.sinh,
    "cosh": math.cosh,
    "tanh": math.tanh,
    "exp": math.exp,
    "log": math.log,
    "log10": math.log10,
    "log2": math.log2,
    "fabs": math.fabs,
    "floor": math.floor,
    "ceil": math.ceil,
    "round": lambda x: math.copysign(math.floor(abs(x) + 0.5), x),  # C's round: half away
    "trunc": math.trunc,
    "cbrt": lambda x: math.copysign(abs(x) ** (1 / 3), x),
}
_MATH_2: dict[str, Callable[[float, float], float]] = {
    "atan2": math.atan2,
    "pow": math.pow,
    "hypot": math.hypot,
    "fmod": math.fmod,
    "fmin": min,
    "fmax": max,
}
# integer casts: (bits, signed); LP64 as Miro's Linux builds
_INT_CASTS = {
    "char": (8, True),
    "signed char": (8, True),
    "unsigned char": (8, False),
    "short": (16, True),
    "short int": (16, True),
    "unsigned short": (16, False),
    "unsigned short int": (16, False),
    "int": (32, True),
    "signed": (32, True),
    "signed int": (32, True),
    "unsigned": (32, False),
    "unsigned int": (32, False),
    "long": (64, True),
    "long int": (64, True),
    "long long": (64, True),
    "unsigned long": (64, False),
    "unsigned long int": (64, False),
    "unsigned long long": (64, False),
    "CORBA::Short": (16, True),
    "CORBA::UShort": (16, False),
    "CORBA::Long": (32, True),
    "CORBA::ULong": (32, False),
    "CORBA::LongLong": (64, True),
    "CORBA::ULongLong": (64, False),
}
_FLOAT_CASTS = frozenset(["double", "float", "CORBA::Double", "CORBA::Float"])
_BOOL_CASTS = frozenset(["bool", "CORBA::Boolean"])

Lookup = Callable[[str], Value | None]


@cache
def parser() -> lark.Lark:
    """The `<constructor>` grammar, with `start` (statements) and `default_args` as entries."""
    return lark.Lark.open(
        str(Path(__file__).with_name("constructor.lark")),
        parser="lalr",
        start=["start", "default_args"],
        propagate_positions=True,
        maybe_placeholders=False,
    )


def evaluate_args(text: str, lookup: Lookup | None = None) -> list[Value]:
    """The values of `text`: one expression, or several separated by commas."""
    if too_deep(text):
        raise ExprError(f"brackets nested more than {MAX_NESTING} deep")
    try:
        tree = parser().parse(text, start="default_args")
        evaluator = Evaluator(lookup)
        return [evaluator.eval(c) for c in tree.children if isinstance(c, lark.Tree)]
    except lark.exceptions.UnexpectedInput as e:
        token = getattr(e, "token", None)
        if token is not None and token.type == "$END":
            raise ExprError("the expression ends too early") from None
        got = str(token) if token is not None else getattr(e, "char", "") or "input"
        raise ExprError(f"{got!r} is not part of a C++ constant expression") from None
    except RecursionError:
        raise ExprError("the expression is nested too deeply") from None


def is_number(v: Value) -> bool:
    return isinstance(v, (bool, int, float))


def to_float(v: Value) -> float:
    if not is_number(v):
        raise ExprError(f"{describe(v)} is not a number")
    return float(v)  # type: ignore[arg-type]


def to_int(v: Value) -> tuple[int, bool]:
    """An integer and whether it was truncated from a double (as C++ converts)."""
    if isinstance(v, float):
        if not math.isfinite(v) or abs(v) >= 2.0**64:
            raise ExprValueError(f"{v} cannot be stored in an integer")
        return math.trunc(v), v != math.trunc(v)
    if isinstance(v, (bool, int)):
        return int(v), False
    raise ExprError(f"{describe(v)} is not a number")


def to_bool(v: Value) -> bool:
    if not is_number(v):
        raise ExprError(f"{describe(v)} is not a number or bool")
    return bool(v)


def describe(v: Value) -> str:
    if isinstance(v, TimeValue):
        return f"ACE_Time_Value({v.sec}, {v.usec})"
    if isinstance(v, Symbol):
        return v.name
    if isinstance(v, str):
        return f"the string {v!r}"
    return repr(v)


def _unescape(raw: str) -> str:
    escapes = {"n": "\n", "t": "\t", "\\": "\\", '"': '"', "'": "'", "0": "\0", "r": "\r"}
    out: list[str] = []
    i = 0
    while i < len(raw):
        c = raw[i]
        if c == "\\" and i + 1 < len(raw):
            nxt = raw[i + 1]
            if nxt not in escapes:
                raise ExprError(f"the escape \\{nxt} is not supported")
            out.append(escapes[nxt])
            i += 2
            continue
        out.append(c)
        i += 1
    return "".join(out)


class Evaluator:
    """Evaluates expression trees of `constructor.lark` to Python values."""

    def __init__(self, lookup: Lookup | None = None) -> None:
        self.lookup = lookup

    def eval(self, node: Any) -> Value:
        method = getattr(self, f"e_{node.data}", None) if isinstance(node, lark.Tree) else None
        if method is None:
            what = node.data if isinstance(node, lark.Tree) else repr(node)
            raise ExprError(f"{what} is not part of a constant expression")
        result: Value = method(node)
        return result

    def e_number(self, node: lark.Tree[Any]) -> Value:
        return parse_number(str(node.children[0]))

    def e_string(self, node: lark.Tree[Any]) -> Value:
        return _unescape(str(node.children[0])[1:-1])

    def e_true(self, node: lark.Tree[Any]) -> Value:
        return True

    def e_false(self, node: lark.Tree[Any]) -> Value:
        return False

    def e_ref(self, node: lark.Tree[Any]) -> Value:
        path = node.children[0]
        if len(path.children) != 1:
            raise ExprError(f"{_path_text(path)} is not a constant")
        return self.name(str(path.children[0]))

    def name(self, name: str) -> Value:
        bare = name.lstrip(":")
        for key in (bare, bare.removeprefix("std::")):
            if key in CONSTANTS:
                return CONSTANTS[key]
            if key in SYMBOLS:
                return Symbol(key)
            if key in _TIME_CONSTANTS:
                return _TIME_CONSTANTS[key]
        if self.lookup is not None:
            found = self.lookup(bare)
            if found is not None:
                return found
        raise ExprError(f"unknown name {name!r}")

    def e_neg(self, node: lark.Tree[Any]) -> Value:
        v = self._number(self.eval(node.children[0]), "-")
        if isinstance(v, float):
            return Float32(-v) if isinstance(v, Float32) else -v
        return typed(-v, int_type(v))

    def e_not_(self, node: lark.Tree[Any]) -> Value:
        return not to_bool(self.eval(node.children[0]))

    def e_cast(self, node: lark.Tree[Any]) -> Value:
        ctype = " ".join(str(t) for t in node.children[0].children)
        v = self.eval(node.children[1])
        return self.cast(ctype, v)

    def cast(self, ctype: str, v: Value) -> Value:
        if ctype in _FLOAT_CASTS:
            value = to_float(v)
            return Float32(value) if "Float" in ctype or ctype == "float" else value
        if ctype in _BOOL_CASTS:
            return to_bool(v)
        if ctype in _INT_CASTS:
            bits, signed = _INT_CASTS[ctype]
            n = to_int(v)[0]
            lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
            if isinstance(v, float) and not lo <= n <= hi:
                raise ExprValueError(f"{v} does not fit in {ctype} (undefined in C++)")
            return cast_int(n, bits, signed)
        raise ExprError(f"a cast to {ctype} is not supported")

    def e_binop(self, node: lark.Tree[Any]) -> Value:
        left, op_token, right = node.children
        op = str(op_token)
        a, b = self.eval(left), self.eval(right)
        if op == "+" and isinstance(a, str) and isinstance(b, str):
            raise ExprError("adding two string literals is not C++")
        x, y = self._number(a, op), self._number(b, op)
        if isinstance(x, float) or isinstance(y, float):
            return floating_result(self._floating(op, float(x), float(y)), x, y)
        ctype = common_type(int_type(x), int_type(y))
        i, j = ctype.wrap(int(x)), ctype.wrap(int(y))
        if op == "+":
            return typed(i + j, ctype)
        if op == "-":
            return typed(i - j, ctype)
        if op == "*":
            return typed(i * j, ctype)
        if j == 0:
            raise ExprValueError(f"integer {'division' if op == '/' else 'remainder'} by zero")
        q = abs(i) // abs(j)
        q = q if (i >= 0) == (j >= 0) else -q  # C++ truncates towards zero
        return typed(q if op == "/" else i - q * j, ctype)

    def _floating(self, op: str, x: float, y: float) -> float:
        if op == "+":
            return x + y
        if op == "-":
            return x - y
        if op == "*":
            return x * y
        if op == "%":
            raise ExprError("% needs integers (C++ has fmod for doubles)")
        if y == 0:
            if x == 0 or math.isnan(x):
                return math.nan
            return math.copysign(math.inf, x) * math.copysign(1.0, y)
        return x / y

    def e_invert(self, node: lark.Tree[Any]) -> Value:
        v = self._integer(self.eval(node.children[0]), "~")
        return typed(~v, int_type(v))

    def e_shift_(self, node: lark.Tree[Any]) -> Value:
        left, op, right = node.children
        a = self._integer(self.eval(left), str(op))
        b = self._integer(self.eval(right), str(op))
        ctype = int_type(a)  # the promoted left operand's type
        if not 0 <= b < ctype.bits:
            raise ExprValueError(f"a shift by {b} is undefined in C++")
        value = ctype.wrap(int(a))
        return typed(value << b if str(op) == "<<" else value >> b, ctype)

    def _bits(self, node: lark.Tree[Any], op: str) -> Value:
        a, b = (self._integer(self.eval(c), op) for c in node.children)
        ctype = common_type(int_type(a), int_type(b))
        i, j = ctype.wrap(int(a)), ctype.wrap(int(b))
        return typed({"|": i | j, "^": i ^ j, "&": i & j}[op], ctype)

    def e_bit_or_(self, node: lark.Tree[Any]) -> Value:
        return self._bits(node, "|")

    def e_bit_xor_(self, node: lark.Tree[Any]) -> Value:
        return self._bits(node, "^")

    def e_bit_and_(self, node: lark.Tree[Any]) -> Value:
        return self._bits(node, "&")

    def _integer(self, v: Value, op: str) -> int:
        if isinstance(v, bool):
            return int(v)
        if isinstance(v, int):
            return v
        raise ExprError(f"{op} needs integers, not {describe(v)}")

    def e_compare(self, node: lark.Tree[Any]) -> Value:
        left, op_token, right = node.children
        a, b = self.eval(left), self.eval(right)
        op = str(op_token)
        if isinstance(a, str) or isinstance(b, str) or not (is_number(a) and is_number(b)):
            raise ExprError(f"{op} compares numbers")
        x: int | float
        y: int | float
        if isinstance(a, float) or isinstance(b, float):
            x, y = float(a), float(b)  # type: ignore[arg-type]
        else:  # -1 < 0u is false in C++: both are converted to unsigned
            ctype = common_type(int_type(a), int_type(b))  # type: ignore[arg-type]
            x, y = ctype.wrap(int(a)), ctype.wrap(int(b))  # type: ignore[arg-type]
        return {
            "<": x < y,
            ">": x > y,
            "<=": x <= y,
            ">=": x >= y,
            "==": x == y,
            "!=": x != y,
        }[op]

    def _branch(self, node: Any, taken: bool) -> Value | None:
        """A branch C++ type-checks, evaluated only when taken (None when not, and it has
        no value)."""
        try:
            return self.eval(node)
        except ExprValueError:
            if taken:
                raise
            return None

    def e_and_(self, node: lark.Tree[Any]) -> Value:
        a = to_bool(self.eval(node.children[0]))
        b = self._branch(node.children[1], a)
        return a and to_bool(b) if b is not None else False

    def e_or_(self, node: lark.Tree[Any]) -> Value:
        a = to_bool(self.eval(node.children[0]))
        b = self._branch(node.children[1], not a)
        return a or (to_bool(b) if b is not None else False)

    def e_cond(self, node: lark.Tree[Any]) -> Value:
        # both branches must have values: the result's type depends on both
        c, x, y = (self.eval(n) for n in node.children)
        chosen = x if to_bool(c) else y
        if isinstance(x, float) or isinstance(y, float):
            if is_number(x) and is_number(y):  # C++'s usual arithmetic conversions
                return floating_result(float(chosen), x, y)  # type: ignore[arg-type]
        elif isinstance(x, int) and isinstance(y, int) and isinstance(chosen, int):
            ctype = common_type(int_type(x), int_type(y))
            return typed(ctype.wrap(chosen), ctype)
        return chosen

    def e_call(self, node: lark.Tree[Any]) -> Value:
        path = node.children[0]
        args = [self.eval(a) for a in node.children[1:] if isinstance(a, lark.Tree)]
        if len(path.children) != 1:
            raise ExprError(f"calling {_path_text(path)}() is not supported")
        name = str(path.children[0]).lstrip(":")
        base = name.removeprefix("std::")
        if name in ("Miro::deg2Rad", "deg2Rad", "Miro::rad2Deg", "rad2Deg"):
            (x,) = self._args(args, 1, name)
            factor = math.pi / 180 if name.endswith("deg2Rad") else 180 / math.pi
            return to_float(x) * factor
        if name == "ACE_Time_Value":
            if not 1 <= len(args) <= 2:
                raise ExprError("ACE_Time_Value(sec, usec) takes one or two numbers")
            sec = to_int(args[0])[0]
            usec = to_int(args[1])[0] if len(args) == 2 else 0
            return TimeValue(sec, usec)
        if name in ("std::string", "string"):
            (x,) = self._args(args, 1, name)
            if not isinstance(x, str):
                raise ExprError("std::string() takes a string")
            return x
        if base in ("abs", "labs", "llabs") and name in (base, f"std::{base}"):
            (x,) = self._args(args, 1, name)
            return abs(self._number(x, name))
        if base in ("min", "max") and name == f"std::{base}":
            a, b = (self._number(v, name) for v in self._args(args, 2, name))
            return min(a, b) if base == "min" else max(a, b)
        if name in (base, f"std::{base}"):
            try:
                if base in _MATH_1:
                    (x,) = self._args(args, 1, name)
                    return float(_MATH_1[base](to_float(x)))
                if base in _MATH_2:
                    x, y = self._args(args, 2, name)
                    return float(_MATH_2[base](to_float(x), to_float(y)))
            except (ValueError, OverflowError, ZeroDivisionError):
                # C's functions return NaN or infinity; a default that is one is a mistake
                raise ExprValueError(f"{name}() is not defined for these arguments") from None
        raise ExprError(f"the function {name}() is not supported")

    def _args(self, args: list[Value], n: int, name: str) -> list[Value]:
        if len(args) != n:
            raise ExprError(f"{name}() takes {n} argument(s), not {len(args)}")
        return args

    def _number(self, v: Value, op: str) -> int | float:
        if isinstance(v, bool):
            return int(v)
        if isinstance(v, (int, float)):
            return v
        raise ExprError(f"{op} needs numbers, not {describe(v)}")


def _path_text(node: lark.Tree[Any]) -> str:
    out = str(node.children[0])
    for seg in node.children[1:]:
        out += f".{seg.children[0]}" if seg.data == "member" else "[...]"
    return out
