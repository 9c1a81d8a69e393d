"""`default="..."` attributes to Python expressions, with makeParams' meaning.

makeParams wrote `member(DEFAULT)` into the C++ constructor, after wrapping the text by type:
strings, `ACE_INET_Addr`s and enumerations were quoted (`"DEFAULT"`), a `char` became
`'DEFAULT'`, an angle `Miro::deg2Rad(DEFAULT)`; everything else was pasted as it was. So numbers
and bools are C++ expressions (`150*1024*1024`, `M_PI/2`), an `ACE_Time_Value` or an
`ACE_Sched_Params` takes its constructor's arguments (`"0, 100000"`, `"ACE_SCHED_FIFO, 50"`), and a
vector its size and fill value (`"3"`, `"3, 1.5"`). Expressions are evaluated by
`expressions.py` (never `eval`); each value is then checked as the run-time reader checks a
document's (ranges, enumeration values). A default that is not C++ but is what the run-time reader
accepts (`yes`, `1.5` seconds, `"1 2 3"` for a vector's elements) is taken as the reader would.
"""

from __future__ import annotations

import math
import re

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.params.compiler.expressions import (
    ExprError,
    Lookup,
    Symbol,
    TimeValue,
    Value,
    describe,
    evaluate_args,
    to_bool,
    to_float,
    to_int,
)
from miro_gen.params.compiler.pymodel import PyType, pyrepr
from miro_gen.params.runtime import codecs, values

_INTEGERS = (
    codecs.SHORT,
    codecs.USHORT,
    codecs.INT,
    codecs.UINT,
    codecs.LONG,
    codecs.ULONG,
)
_SCHED_POLICIES: dict[object, str] = {
    "ACE_SCHED_OTHER": "SCHED_OTHER",
    "ACE_SCHED_FIFO": "SCHED_FIFO",
    "ACE_SCHED_RR": "SCHED_RR",
    0: "SCHED_OTHER",  # Linux's numbers, which ACE uses there
    1: "SCHED_FIFO",
    2: "SCHED_RR",
}
_SCHED_SCOPES = ("ACE_SCOPE_THREAD", "ACE_SCOPE_PROCESS", "ACE_SCOPE_LWP")
MAX_ELEMENTS = 1_000_000  # `default="N"` of a vector: N elements


class DefaultError(Exception):
    """A default that cannot be the parameter's value; the message says why."""


class DefaultCompiler:
    """Turns one item's `default=` texts into Python expressions (errors in `diag`)."""

    def __init__(self, diag: Diagnostics, lookup: Lookup | None = None) -> None:
        self.diag = diag
        self.lookup = lookup

    def expression(self, t: PyType, text: str, pos: SourcePos) -> tuple[str | None, str | None]:
        """(default, default_factory) for a field of type `t`; (None, None) after an error."""
        try:
            if t.element is not None:
                return None, self.vector(t, text, pos)
            if t.struct_target is not None:
                return None, self.struct(t, text)
            return self.scalar(t, text, pos), None
        except DefaultError as e:
            self.diag.error(pos, f"default={text!r}: {e}")
            return None, None

    # -- scalars ------------------------------------------------------------------------------

    def scalar(self, t: PyType, text: str, pos: SourcePos) -> str:
        codec = t.runtime
        if codec is None or not isinstance(codec, codecs.Scalar):
            raise DefaultError(f"a {t.spelling} cannot have a default=; use a <constructor> block")
        if t.choices or codec in (codecs.STRING, codecs.CHAR, codecs.INET_ADDR):
            return value_literal(codec, self._check(codec, text))  # quoted by makeParams
        if t.scalar_codec is not None and not t.scalar_codec.startswith("_rt."):
            return value_literal(codec, self._check(codec, text))  # a Python helper's type
        try:
            return self._evaluated(codec, evaluate_args(text, self.lookup), pos, text)
        except (ExprError, DefaultError) as e:
            try:  # not C++, but what the run-time reader takes (yes, 1.5 seconds)
                return value_literal(codec, codec.parse(text))
            except ValueError:
                raise DefaultError(str(e)) from None

    def _evaluated(self, codec: codecs.Scalar, args: list[Value], pos: SourcePos, text: str) -> str:
        if codec is codecs.TIME:
            return _time_literal(args)
        if len(args) != 1:
            raise DefaultError(f"one value expected for a {codec.label}, got {len(args)}")
        (v,) = args
        if isinstance(v, (TimeValue, Symbol, str)):
            raise DefaultError(f"{describe(v)} is not a {codec.label}")
        if codec is codecs.BOOL:
            return "True" if to_bool(v) else "False"
        if codec is codecs.ANGLE:  # makeParams: Miro::deg2Rad(DEFAULT)
            degrees = to_float(v)
            self._check(codecs.DOUBLE, _float_text(degrees))
            return f"_rt.deg2rad({_float_code(degrees)})"
        if codec in _INTEGERS:
            n, truncated = to_int(v)
            if truncated:
                self.diag.warning(pos, f"default={text!r}: {v!r} is truncated to {n}, as C++ did")
            return pyrepr(self._check(codec, str(n)))
        x = to_float(v)
        self._check(codec, _float_text(x))
        return _float_code(x)

    def _check(self, codec: codecs.Scalar, text: str) -> object:
        try:
            return codec.parse(text)
        except ValueError as e:
            raise DefaultError(str(e)) from None

    # -- structures and vectors ---------------------------------------------------------------

    def struct(self, t: PyType, text: str) -> str:
        if t.struct_target == "_rt.SchedParams":
            return sched_params_factory(self._args(text))
        raise DefaultError(f"a {t.spelling} cannot have a default=; use a <constructor> block")

    def vector(self, t: PyType, text: str, pos: SourcePos) -> str:
        """makeParams: `std::vector<T>(DEFAULT)`, so `"N"` is N default elements and `"N, x"`
        N copies of x. Also read: the elements themselves (`"1 2 3"`, as a document gives
        them), and the values of an EnumerationMultiple (`"A B"`)."""
        elem = t.element
        assert elem is not None
        if t.choices_multiple:
            assert isinstance(elem.runtime, codecs.Scalar)
            return self._elements(t, elem.runtime, text)
        if not t.unique:
            try:
                args = evaluate_args(text, self.lookup)
            except ExprError:
                args = []
            if 1 <= len(args) <= 2 and isinstance(args[0], (int, bool)):
                return self._sized(t, elem, args, pos, text)
        if isinstance(elem.runtime, codecs.Scalar):
            return self._elements(t, elem.runtime, text)
        raise DefaultError(f"a {t.spelling} takes its elements from a <constructor> block")

    def _sized(self, t: PyType, elem: PyType, args: list[Value], pos: SourcePos, text: str) -> str:
        n = to_int(args[0])[0]
        if not 0 <= n <= MAX_ELEMENTS:
            raise DefaultError(f"{n} elements: a vector takes 0 to {MAX_ELEMENTS}")
        if len(args) == 2:
            if elem.runtime is None or not isinstance(elem.runtime, codecs.Scalar):
                raise DefaultError(f"{elem.spelling} elements cannot be given a value here")
            fill = self._evaluated(elem.runtime, [args[1]], pos, text)
        elif elem.runtime is not None:
            fill = value_literal(elem.runtime, elem.runtime.default())
        else:
            assert elem.factory is not None
            return f"lambda: [{elem.factory}() for _ in range({n})]"
        return f"lambda: [{fill}] * {n}"

    def _elements(self, t: PyType, scalar: codecs.Scalar, text: str) -> str:
        items = [s for s in re.split(r"[\s,;]+", text.strip()) if s]
        out = [value_literal(scalar, self._check(scalar, s)) for s in items]
        body = ", ".join(out)
        if t.unique:
            return f"lambda: {{{body}}}" if out else "set"
        return f"lambda: [{body}]"

    def _args(self, text: str) -> list[Value]:
        try:
            return evaluate_args(text, self.lookup)
        except ExprError as e:
            raise DefaultError(str(e)) from None


def sched_params_factory(args: list[Value]) -> str:
    """`ACE_Sched_Params(policy, priority, scope, quantum)` as a default factory."""
    if not 1 <= len(args) <= 4:
        raise DefaultError("ACE_Sched_Params takes policy, priority, scope and quantum")
    key: object = args[0].name if isinstance(args[0], Symbol) else args[0]
    policy = _SCHED_POLICIES.get(key)
    if policy is None:
        raise DefaultError(f"{describe(args[0])} is not a scheduling policy (ACE_SCHED_FIFO, ...)")
    parts = [f"policy={pyrepr(policy)}"]
    if len(args) > 1:
        try:
            priority = to_int(args[1])[0]
        except ExprError as e:
            raise DefaultError(str(e)) from None
        parts.append(f"priority={priority}")
    if len(args) > 2:
        scope = args[2]
        if not isinstance(scope, Symbol) or scope.name not in _SCHED_SCOPES:
            raise DefaultError(f"{describe(scope)} is not a scope (ACE_SCOPE_THREAD, ...)")
        parts.append(f"scope={pyrepr(scope.name)}")
    if len(args) > 3:
        parts.append(f"quantum={_time_literal([args[3]])}")
    return f"lambda: _rt.SchedParams({', '.join(parts)})"


def _time_literal(args: list[Value]) -> str:
    """`ACE_Time_Value(DEFAULT)`: `"sec, usec"`, `"sec"` or an `ACE_Time_Value(...)`."""
    try:
        if len(args) == 1 and isinstance(args[0], TimeValue):
            tv = args[0]
        elif len(args) == 1:
            sec, _ = to_int(args[0])
            tv = TimeValue(sec, 0)
            if isinstance(args[0], float) and args[0] != sec:
                raise DefaultError(
                    'an ACE_Time_Value takes "sec, usec" (makeParams refused a dot here)'
                )
        elif len(args) == 2:
            if any(isinstance(a, float) for a in args):
                raise DefaultError('an ACE_Time_Value takes whole "sec, usec" (no dot)')
            tv = TimeValue(to_int(args[0])[0], to_int(args[1])[0])
        else:
            raise DefaultError('an ACE_Time_Value takes "sec, usec"')
    except ExprError as e:
        raise DefaultError(str(e)) from None
    return value_literal(codecs.TIME, values.time_value(tv.sec, tv.usec))


def _float_text(x: float) -> str:
    return repr(x)


def _float_code(x: float) -> str:
    """A float as Python source (`float("inf")` where repr would say `inf`)."""
    if math.isnan(x):
        return 'float("nan")'
    if math.isinf(x):
        return 'float("inf")' if x > 0 else '-float("inf")'
    return repr(x)


def value_literal(codec: codecs.Codec, value: object) -> str:
    """A Python expression for a value the codec parsed."""
    if codec is codecs.ANGLE:
        assert isinstance(value, float)
        return f"_rt.deg2rad({codecs.format_float(values.rad2deg(value))})"
    if codec is codecs.TIME:
        sec, usec = values.format_time_value(value).split(", ")  # type: ignore[arg-type]
        return f"_rt.time_value({sec}, {usec})"
    if codec is codecs.INET_ADDR:
        assert isinstance(value, values.InetAddr)
        return f"_rt.InetAddr({pyrepr(value.host)}, {value.port})"
    if isinstance(value, float):
        return _float_code(value)
    return pyrepr(value)
