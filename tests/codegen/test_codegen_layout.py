"""The line-breaking rule of the generated code (miro_gen/codegen/layout.py): what fits stays on
one line, what does not is exploded as ruff formats it."""

from __future__ import annotations

from miro_gen.codegen.layout import bracket, wrap
from miro_gen.codegen.render import environment


def test_a_call_that_fits_stays_on_one_line_up_to_the_limit() -> None:
    call = bracket("f(", ["a", "b"], ")")
    assert wrap(call, limit=7) == "f(a, b)"  # exactly the limit
    assert wrap(call, limit=6) == "f(\n    a,\n    b,\n)"


def test_an_exploded_call_has_one_item_a_line_with_a_trailing_comma() -> None:
    call = bracket("x, _off = _cdr.get_string(", ["_data", "_off", "_e", "None", "'w'"], ")")
    assert wrap(call, limit=20).split("\n") == [
        "x, _off = _cdr.get_string(",
        "    _data,",
        "    _off,",
        "    _e,",
        "    None,",
        "    'w',",
        ")",
    ]


def test_hugging_keeps_the_items_together_without_a_trailing_comma() -> None:
    sig = bracket("def f(", ["a: int, b: int"], ") -> None:", hug=True)
    assert wrap(sig, limit=100) == "def f(a: int, b: int) -> None:"
    assert wrap(sig, limit=10) == "def f(\n    a: int, b: int\n) -> None:"


def test_parentheses_only_when_exploded() -> None:
    unpack = bracket("(", ["a", "b"], ") = _results", flat_head="", flat_tail=" = _results")
    assert wrap(unpack, limit=100) == "a, b = _results"
    assert wrap(unpack, limit=5) == "(\n    a,\n    b,\n) = _results"


def test_an_exploded_construct_explodes_what_it_contains() -> None:
    inner = bracket("Point(", ["x", "y"], ")")
    ret = bracket("return (", [inner, "_off"], ")", flat_head="return ", flat_tail="")
    assert wrap(ret, limit=100) == "return Point(x, y), _off"
    assert wrap(ret, limit=10).split("\n") == [
        "return (",
        "    Point(",
        "        x,",
        "        y,",
        "    ),",
        "    _off,",
        ")",
    ]


def test_an_items_limit_measures_the_items_only() -> None:
    pack = bracket("_buf += _P12(", ["a" * 30, "b" * 28], ")")
    assert "\n" not in wrap(pack, limit=10, items_limit=60)
    assert wrap(pack, limit=1000, items_limit=59).count("\n") == 3


def test_templates_use_it_with_indentation() -> None:
    env = environment()
    text = env.from_string("    {{ bracket('f(', args, ')') | wrap(12) | indent(4) }}\n").render(
        args=["alpha", "beta"]
    )
    assert text == "    f(\n        alpha,\n        beta,\n    )\n"
