"""`default=` expressions evaluated as C++ evaluates them: random expressions checked against
g++ (the oracle: makeParams pasted these texts into C++), and random text that only ever ends
in a value or an `ExprError`, never in another exception."""

from __future__ import annotations

import math
import random
import shutil
import subprocess
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from params_helpers import SETTINGS

from miro_gen.params.compiler.expressions import ExprError, evaluate_args

_INTS = ["0", "1", "2", "3", "7", "10", "42", "100", "0x1F", "010", "5L", "3u"]
_DOUBLES = ["0.5", "2.5", "1e2", ".25", "3.", "1.5f", "M_PI", "M_PI_2"]
_BINARY = ["+", "-", "*", "/", "%", "<", ">", "<=", ">=", "==", "!=", "&&", "||", "&", "|", "^"]
_CASTS = ["(int)", "(double)", "(long)", "(bool)", "(unsigned int)", "(short)", "(float)"]
_FUNCS = ["sqrt", "fabs", "floor", "ceil", "Miro::deg2Rad", "Miro::rad2Deg", "cos", "atan2"]


def _expression(rng: random.Random, depth: int) -> str:
    """A random C++ expression of literals, operators, casts and <cmath> functions."""
    roll = rng.random()
    if depth == 0 or roll < 0.25:
        return rng.choice(_INTS if rng.random() < 0.6 else _DOUBLES)
    if roll < 0.55:
        op = rng.choice(_BINARY)
        return f"({_expression(rng, depth - 1)} {op} {_expression(rng, depth - 1)})"
    if roll < 0.65:
        return f"{rng.choice(['-', '!', '~'])} {_expression(rng, depth - 1)}"
    if roll < 0.75:
        return f"{rng.choice(_CASTS)}{_expression(rng, depth - 1)}"
    if roll < 0.82:
        c, a, b = (_expression(rng, depth - 1) for _ in range(3))
        return f"({c} ? {a} : {b})"
    if roll < 0.9:
        return f"({_expression(rng, depth - 1)} << {rng.randrange(0, 12)})"
    fn = rng.choice(_FUNCS)
    args = ", ".join(_expression(rng, depth - 1) for _ in range(2 if fn == "atan2" else 1))
    return f"{fn}({args})"


_PROGRAM = """\
#include <cmath>
#include <cstdio>
namespace Miro {
  inline double deg2Rad(double d) { return d * M_PI / 180.; }
  inline double rad2Deg(double r) { return r * 180. / M_PI; }
}
static void show(bool v) { std::printf("bool %d\\n", v ? 1 : 0); }
static void show(int v) { std::printf("int %d\\n", v); }
static void show(unsigned v) { std::printf("int %u\\n", v); }
static void show(long v) { std::printf("int %ld\\n", v); }
static void show(unsigned long v) { std::printf("int %lu\\n", v); }
static void show(float v) { std::printf("double %.17g\\n", (double)v); }
static void show(double v) { std::printf("double %.17g\\n", v); }
int main() {
%s
  return 0;
}
"""


def _same(ours: object, kind: str, text: str, single: bool) -> bool:
    if kind == "bool":
        return isinstance(ours, bool) and int(ours) == int(text)
    if kind == "int":
        return isinstance(ours, (bool, int)) and int(ours) == int(text)
    theirs = float(text)
    if not isinstance(ours, float):
        return False
    if math.isnan(theirs):
        return math.isnan(ours)
    # <cmath> has float overloads: a function of a float may be computed in single precision
    tolerance = 1e-6 if single else 1e-12
    return ours == theirs or math.isclose(ours, theirs, rel_tol=tolerance, abs_tol=1e-300)


@pytest.mark.skipif(shutil.which("g++") is None, reason="g++ is not installed")
def test_random_expressions_evaluate_as_gcc_does(tmp_path: Path) -> None:
    rng = random.Random(14)
    cases: list[tuple[str, object]] = []
    while len(cases) < 400:
        text = _expression(rng, rng.randrange(1, 5))
        try:
            (value,) = evaluate_args(text)
        except ExprError:
            continue  # division by zero, % of doubles, ...: C++ refuses those too
        if isinstance(value, float) and (math.isinf(value) or abs(value) > 1e300):
            continue
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 2**31:
            continue  # int overflow is undefined in C++: no oracle
        cases.append((text, value))
    body = "\n".join(f"  show({text});" for text, _ in cases)
    src = tmp_path / "exprs.cpp"
    src.write_text(_PROGRAM.replace("%s", body, 1))
    exe = tmp_path / "exprs"
    build = subprocess.run(
        ["g++", "-std=c++17", "-w", "-O0", "-o", str(exe), str(src)],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert build.returncode == 0, build.stderr[-3000:]
    lines = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60).stdout
    results = lines.splitlines()
    assert len(results) == len(cases)
    wrong = [
        (text, ours, line)
        for (text, ours), line in zip(cases, results, strict=True)
        if not _same(ours, *line.split(" ", 1), single="f" in text or "float" in text)
    ]
    assert not wrong, "\n".join(f"{t}: ours {o!r}, g++ {g}" for t, o, g in wrong[:20])


_TOKENS = st.sampled_from(
    [*_INTS, *_DOUBLES, *_BINARY, "(", ")", ",", "?", ":", "!", "~", "-", "<<", ">>", "x", "y.z",
     "a[1]", "f(", "INFINITY", "NAN", "ACE_Time_Value(", "ACE_SCHED_FIFO", '"s"', "'c'", "@",
     "sqrt(", "std::", "::", "1e999", "0x", "(int)", "(string)", "true", "false"]
)  # fmt: skip


@settings(SETTINGS, max_examples=400)
@given(tokens=st.lists(_TOKENS, max_size=12))
def test_any_text_is_a_value_or_an_expression_error(tokens: list[str]) -> None:
    text = " ".join(tokens)
    try:
        values = evaluate_args(text)
    except ExprError as e:
        assert str(e)
    else:
        assert values and all(v is not None for v in values)


def test_deep_nesting_is_an_error_not_a_crash() -> None:
    with pytest.raises(ExprError, match="nested too deeply"):
        evaluate_args("-" * 5000 + "1")
    assert evaluate_args("(" * 200 + "1" + ")" * 200) == [1]
    # refused by a scan before Lark parses it (Python's own limit: 200 parentheses)
    with pytest.raises(ExprError, match="brackets nested more than 200 deep"):
        evaluate_args("(" * 201 + "1" + ")" * 201)
