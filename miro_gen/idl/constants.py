"""Constant expressions: evaluation with the CORBA typing rules and per-type range checks.

Integers are evaluated exactly; every intermediate value must fit 64 bits (signed or unsigned) and
the result must fit the target type. `~` complements within the target type's width (CORBA 3.0
section 3.10.2: `-(v+1)` for signed types, `2^n - 1 - v` for unsigned ones). Division and `%`
truncate toward zero, as in C. Floating-point and fixed-point values never mix with integers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from decimal import Context, Decimal
from typing import NamedTuple

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast

INT_RANGES: dict[str, tuple[int, int, int, bool]] = {
    "short": (-(2**15), 2**15 - 1, 16, True),
    "unsigned short": (0, 2**16 - 1, 16, False),
    "long": (-(2**31), 2**31 - 1, 32, True),
    "unsigned long": (0, 2**32 - 1, 32, False),
    "long long": (-(2**63), 2**63 - 1, 64, True),
    "unsigned long long": (0, 2**64 - 1, 64, False),
    "int8": (-128, 127, 8, True),
    "uint8": (0, 255, 8, False),
    "octet": (0, 255, 8, False),
}
FLOAT_TYPES = ("float", "double", "long double")
FLT_MAX = 3.4028234663852886e38
FIXED_CONTEXT = Context(prec=31)


class Target(NamedTuple):
    """What a constant expression must produce.

    kind: int, float, fixed, char, wchar, bool, string, wstring, enum, or "any" (annotation
    arguments: whatever the expression is).
    """

    kind: str
    name: str = ""  # the IDL type, for messages and integer ranges
    bound: int | None = None  # string bound, or fixed digits
    scale: int | None = None  # fixed scale
    enum: ast.Enum | None = None

    @property
    def signed(self) -> bool:
        return INT_RANGES.get(self.name, (0, 0, 64, True))[3]

    @property
    def bits(self) -> int:
        return INT_RANGES.get(self.name, (0, 0, 64, True))[2]


ANY = Target("any")
ARRAY_BOUND_MAX = 2**32 - 1


class EvalError(Exception):
    def __init__(self, pos: SourcePos, message: str) -> None:
        super().__init__(message)
        self.pos = pos
        self.message = message


# A name resolver: returns (kind, value) of a constant or enumerator, or raises EvalError.
NameLookup = Callable[[ast.NameRef], tuple[str, ast.ConstValue]]


def plural(kind: str) -> str:
    return {
        "int": "integers",
        "float": "floating-point values",
        "fixed": "fixed-point values",
        "char": "characters",
        "wchar": "wide characters",
        "bool": "booleans",
        "string": "strings",
        "wstring": "wide strings",
        "enum": "enumerators",
    }.get(kind, kind)


def describe(kind: str) -> str:
    return {
        "int": "an integer",
        "float": "a floating-point value",
        "fixed": "a fixed-point value",
        "char": "a character",
        "wchar": "a wide character",
        "bool": "a boolean",
        "string": "a string",
        "wstring": "a wide string",
        "enum": "an enumerator",
        "ident": "an identifier",
    }.get(kind, kind)


class Evaluator:
    def __init__(self, lookup: NameLookup, diag: Diagnostics) -> None:
        self.lookup = lookup
        self.diag = diag

    def evaluate(self, expr: ast.Expr, target: Target) -> ast.ConstValue | None:
        """Evaluate `expr` for `target`; reports an error and returns None when it is invalid."""
        try:
            kind, value = self._eval(expr, target)
            return self._convert(kind, value, target, expr.pos)
        except EvalError as e:
            if e.message:  # empty: already reported (an undeclared name)
                self.diag.error(e.pos, e.message)
            return None

    # -- evaluation ---------------------------------------------------------------------------
    def _eval(self, e: ast.Expr, target: Target) -> tuple[str, ast.ConstValue]:
        if isinstance(e, ast.Literal):
            return e.kind, e.value
        if isinstance(e, ast.NameRef):
            return self.lookup(e)
        if isinstance(e, ast.UnaryOp):
            kind, v = self._eval(e.operand, target)
            return self._unary(e, kind, v, target)
        kl, vl = self._eval(e.left, target)
        kr, vr = self._eval(e.right, target)
        return self._binary(e, kl, vl, kr, vr)

    def _unary(
        self, e: ast.UnaryOp, kind: str, v: ast.ConstValue, target: Target
    ) -> tuple[str, ast.ConstValue]:
        if kind == "int":
            assert isinstance(v, int)
            if e.op == "-":
                return "int", self._check64(-v, e.pos)
            if e.op == "+":
                return "int", v
            if target.kind == "int" and not target.signed:
                if v < 0 or v >= 2**target.bits:
                    raise EvalError(e.pos, f"operand of '~' is out of range for {target.name}")
                return "int", (2**target.bits - 1) - v
            return "int", -(v + 1)
        if kind in ("float", "fixed") and e.op in "-+":
            assert isinstance(v, (float, Decimal))
            return kind, (-v if e.op == "-" else v)
        raise EvalError(e.pos, f"operator '{e.op}' cannot be applied to {plural(kind)}")

    def _binary(
        self, e: ast.BinaryOp, kl: str, vl: ast.ConstValue, kr: str, vr: ast.ConstValue
    ) -> tuple[str, ast.ConstValue]:
        op = e.op
        if kl != kr:
            if {kl, kr} <= {"int", "float", "fixed"}:
                raise EvalError(
                    e.pos,
                    f"cannot combine {describe(kl)} and {describe(kr)} with '{op}' "
                    "(IDL has no implicit conversions)",
                )
            raise EvalError(
                e.pos, f"operator '{op}' cannot combine {describe(kl)} and {describe(kr)}"
            )
        if kl == "int":
            assert isinstance(vl, int) and isinstance(vr, int)
            return "int", self._check64(self._int_op(op, vl, vr, e.pos), e.pos)
        if kl == "float":
            assert isinstance(vl, float) and isinstance(vr, float)
            if op not in "+-*/":
                raise EvalError(e.pos, f"operator '{op}' cannot be applied to {plural(kl)}")
            if op == "/" and vr == 0.0:
                raise EvalError(e.pos, "division by zero")
            result = {"+": vl + vr, "-": vl - vr, "*": vl * vr}.get(op)
            value = result if result is not None else vl / vr
            if math.isinf(value) or math.isnan(value):
                raise EvalError(e.pos, "floating-point overflow in constant expression")
            return "float", value
        if kl == "fixed":
            assert isinstance(vl, Decimal) and isinstance(vr, Decimal)
            if op not in "+-*/":
                raise EvalError(e.pos, f"operator '{op}' cannot be applied to {plural(kl)}")
            if op == "/" and vr == 0:
                raise EvalError(e.pos, "division by zero")
            ctx = FIXED_CONTEXT
            value_d = {
                "+": ctx.add, "-": ctx.subtract, "*": ctx.multiply, "/": ctx.divide,
            }[op](vl, vr)  # fmt: skip
            return "fixed", value_d
        raise EvalError(e.pos, f"operator '{op}' cannot be applied to {plural(kl)}")

    @staticmethod
    def _int_op(op: str, a: int, b: int, pos: SourcePos) -> int:
        if op in ("/", "%"):
            if b == 0:
                raise EvalError(pos, "division by zero")
            q = abs(a) // abs(b)
            if (a < 0) != (b < 0):
                q = -q
            return q if op == "/" else a - q * b
        if op in ("<<", ">>"):
            if not 0 <= b < 64:
                raise EvalError(pos, "right operand of a shift must be between 0 and 63")
            return a << b if op == "<<" else a >> b
        if op == "|":
            return a | b
        if op == "^":
            return a ^ b
        if op == "&":
            return a & b
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        return a * b

    @staticmethod
    def _check64(v: int, pos: SourcePos) -> int:
        if v < -(2**63):
            raise EvalError(pos, f"value {v} is too small for any IDL integer type")
        if v > 2**64 - 1:
            raise EvalError(pos, f"value {v} is too large for any IDL integer type")
        return v

    # -- conversion to the target -------------------------------------------------------------
    def _convert(
        self, kind: str, v: ast.ConstValue, target: Target, pos: SourcePos
    ) -> ast.ConstValue:
        t = target.kind
        if t == "any":
            return v
        if t == "int":
            if kind != "int":
                raise EvalError(pos, f"{describe(kind)} cannot initialise {target.name}")
            assert isinstance(v, int)
            lo, hi, _, _ = INT_RANGES[target.name]
            if v < lo:
                raise EvalError(pos, f"value {v} is too small for {target.name} (minimum {lo})")
            if v > hi:
                raise EvalError(pos, f"value {v} is too large for {target.name} (maximum {hi})")
            return v
        if t == "float":
            if kind != "float":
                raise EvalError(
                    pos,
                    f"{describe(kind)} cannot initialise {target.name}"
                    + (
                        " (write it as a floating-point literal, e.g. 1.0)" if kind == "int" else ""
                    ),
                )
            assert isinstance(v, float)
            limit = FLT_MAX if target.name == "float" else 1.7976931348623157e308
            if abs(v) > limit:
                raise EvalError(pos, f"value {v} is out of range for {target.name}")
            return v
        if t == "fixed":
            if kind not in ("fixed", "int"):
                raise EvalError(pos, f"{describe(kind)} cannot initialise a fixed-point constant")
            d = Decimal(v) if isinstance(v, int) else v
            assert isinstance(d, Decimal)
            digits = len(d.as_tuple().digits)
            if digits > 31:
                raise EvalError(pos, "fixed-point value has more than 31 digits")
            if target.bound is not None and target.scale is not None:
                integer_digits = target.bound - target.scale
                if abs(d) >= Decimal(10) ** integer_digits:
                    raise EvalError(
                        pos, f"value {d} does not fit fixed<{target.bound}, {target.scale}>"
                    )
            return d
        if t in ("char", "wchar"):
            if kind == t:  # narrow and wide literals do not mix (IDL 4.2 section 7.2.6.2.1)
                return v
            hint = " (write L'x' for a wide character)" if kind == "char" else ""
            raise EvalError(pos, f"{describe(kind)} cannot initialise a {t}{hint}")
        if t == "bool":
            if kind != "bool":
                raise EvalError(pos, f"{describe(kind)} cannot initialise a boolean")
            return v
        if t in ("string", "wstring"):
            if kind != t:  # narrow and wide literals do not mix (IDL 4.2 section 7.2.6.3)
                hint = ' (write L"..." for a wide string)' if kind == "string" else ""
                raise EvalError(pos, f"{describe(kind)} cannot initialise a {t}{hint}")
            assert isinstance(v, str)
            if target.bound is not None and len(v) > target.bound:
                raise EvalError(
                    pos, f"string of length {len(v)} is longer than the bound {target.bound}"
                )
            return v
        if t == "enum":
            if kind != "enum" or not isinstance(v, ast.EnumValue) or v.enum is not target.enum:
                name = target.enum.scoped_name if target.enum is not None else "the enum"
                raise EvalError(
                    pos,
                    f"{describe(kind)} cannot initialise {name}: expected one of its enumerators",
                )
            return v
        raise EvalError(pos, f"constants of type {target.name} are not allowed")  # pragma: no cover
