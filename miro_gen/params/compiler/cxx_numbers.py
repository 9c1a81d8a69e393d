"""C++'s numbers as the makeParams compiler's C++ compiler computed them (LP64): integral types
after promotion and the usual arithmetic conversions, unsigned wrap-around, casts that wrap,
`float` as a double rounded to single precision, and number literals with their suffixes. The
errors of expressions (`ExprError`) are defined here, where the first of them is raised."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass


class ExprError(Exception):
    """An expression outside the subset, or one C++ would refuse (division by zero)."""


class ExprValueError(ExprError):
    """A well-formed expression without a value (division by zero): harmless in the branch
    of `&&`, `||` or `?:` that C++ does not evaluate."""


@dataclass(frozen=True)
class IntType:
    """A C++ integral type after promotion: int, unsigned int, long, unsigned long (LP64)."""

    bits: int
    signed: bool

    def wrap(self, value: int) -> int:
        """Unsigned arithmetic is modular in C++ (signed overflow is undefined: kept)."""
        return value if self.signed else value % (1 << self.bits)


INT = IntType(32, True)
UINT = IntType(32, False)
LONG = IntType(64, True)
ULONG = IntType(64, False)


class Integral(int):
    """An integer with its C++ type (plain Python ints are `int`)."""

    ctype: IntType

    def __new__(cls, value: int, ctype: IntType) -> Integral:
        obj = super().__new__(cls, ctype.wrap(value))
        obj.ctype = ctype
        return obj


def int_type(v: bool | int) -> IntType:
    """The promoted type of an integer value (bool, char and short promote to int)."""
    return v.ctype if isinstance(v, Integral) else INT


def common_type(a: IntType, b: IntType) -> IntType:
    """C++'s usual arithmetic conversions of two promoted integral types (LP64)."""
    if a == b:
        return a
    if a.signed == b.signed:
        return a if a.bits > b.bits else b
    signed, unsigned = (a, b) if a.signed else (b, a)
    if unsigned.bits >= signed.bits:
        return unsigned
    return signed  # long holds every unsigned int


def wrap_bits(value: int, bits: int, signed: bool) -> int:
    value &= (1 << bits) - 1
    if signed and value >= 1 << (bits - 1):
        value -= 1 << bits
    return value


class Float32(float):
    """A C++ `float` (a `1.5f` literal, a `(float)` cast): a double rounded to single
    precision. Arithmetic of floats (and integers) stays single; with a double it is double."""

    def __new__(cls, value: float) -> Float32:
        try:
            rounded = struct.unpack("f", struct.pack("f", value))[0]
        except OverflowError:
            raise ExprValueError(f"{value} does not fit in a float") from None
        return super().__new__(cls, rounded)


def floating_result(value: float, *operands: object) -> float:
    """Single precision when no operand is a double."""
    if any(isinstance(o, float) and not isinstance(o, Float32) for o in operands):
        return value
    return Float32(value) if math.isfinite(value) else value


def cast_int(value: int, bits: int, signed: bool) -> int:
    """A conversion to an integral type: wraps modulo 2^bits, typed when 32 bits or more."""
    wrapped = wrap_bits(value, bits, signed)
    if bits < 32:
        return wrapped  # promotes to int
    return Integral(wrapped, IntType(bits, signed))


def parse_number(text: str) -> int | float:
    """A C++ number literal: suffixes, hexadecimal, octal (`010` is 8); an integer gets the
    first of C++'s types that holds it (`3u` is unsigned, `0xFFFFFFFF` unsigned int)."""
    t = text
    suffix = ""
    while t and t[-1] in "uUlL" and not (t.lower().startswith("0x") and t[-1] in "fF"):
        suffix, t = t[-1].lower() + suffix, t[:-1]
    if t.lower().startswith("0x"):
        return _typed_literal(int(t, 16), suffix, decimal=False)
    body = t.rstrip("fF") if "." in t or "e" in t.lower() else t
    if body.isdigit():
        octal = len(body) > 1 and body[0] == "0"
        return _typed_literal(int(body, 8 if octal else 10), suffix, decimal=not octal)
    try:
        value = float(body)
    except ValueError:
        raise ExprError(f"{text!r} is not a number") from None
    return Float32(value) if body != t else value


def _typed_literal(value: int, suffix: str, decimal: bool) -> int:
    unsigned = "u" in suffix
    long_ = "l" in suffix
    choices = [LONG, ULONG] if long_ else [INT, UINT, LONG, ULONG]
    if unsigned:
        choices = [c for c in choices if not c.signed]
    elif decimal:
        choices = [c for c in choices if c.signed]  # a decimal literal is never unsigned
    for c in choices:
        if value < (1 << (c.bits - 1) if c.signed else 1 << c.bits):
            return value if c == INT else Integral(value, c)
    raise ExprError(f"{value} is too large for any C++ integer type")


def typed(value: int, ctype: IntType) -> int:
    return value if ctype == INT else Integral(value, ctype)
