"""Names that are Python keywords or builtins, and values that do not fit: BAD_PARAM on the
client, nothing sent."""

from __future__ import annotations

import inspect
import keyword
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest
from stub_support import NO, CountingInvoker

from miro_gen.exceptions import (
    BAD_PARAM,
)

# =============================================================================================
# names that are Python keywords or builtins
# =============================================================================================


def _method(cls: type, idl_name: str) -> str:
    """The Python name of an operation: the IDL name or, escaped, with a leading underscore."""
    for name in (idl_name, "_" + idl_name):
        if name in vars(cls):
            return name
    raise AssertionError(f"{cls.__name__} has no method for IDL operation {idl_name}")


def test_keyword_names_are_escaped(gen: SimpleNamespace) -> None:
    Rpc, POA = gen.Rpc, gen.POA
    # wire names are the IDL names
    assert set(POA.Keywords._dispatch) == {
        "print",
        "lambda",
        "None",
        "sum",
        "_get_pass",
        "_set_pass",
        "_get_def",
    }
    for cls in (Rpc.Keywords, POA.Keywords):
        # Python keywords get a leading underscore (OMG IDL-to-Python mapping)
        assert "_lambda" in vars(cls) and "_None" in vars(cls)
        assert next(iter(inspect.signature(cls._lambda).parameters)) == "self"
        params = list(inspect.signature(cls._None).parameters)
        assert params[:3] == ["self", "_class", "_self"]  # `self` would clash with self
        from_ = list(inspect.signature(getattr(cls, _method(cls, "print"))).parameters)
        assert from_ == ["self", "_from"]
        assert {"_get_pass", "_set_pass", "_get_def"} <= set(vars(cls))
        assert "_set_def" not in vars(cls)
        # builtins: escaped or not, but always valid, non-keyword, distinct identifiers
        for op in ("_lambda", "_None", _method(cls, "sum")):
            names = list(inspect.signature(getattr(cls, op)).parameters)
            assert len(set(names)) == len(names)
            for n in names:
                assert n.isidentifier() and not keyword.iskeyword(n), (op, n)
    builtin_params = list(inspect.signature(Rpc.Keywords._None).parameters)[3:]
    assert [n.lstrip("_") for n in builtin_params] == ["bytes", "list", "len"]


def test_keyword_operations_work(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc = gen.Rpc
    servant = gen.impl.Keywords()
    k = inv.stub(Rpc.Keywords, servant)
    assert getattr(k, _method(Rpc.Keywords, "print"))(5) is None
    assert k._lambda("four") == 4
    assert k._None(1, 2, 3, 4, 5) == 54321  # parameters named class, self, bytes, list, len
    assert getattr(k, _method(Rpc.Keywords, "sum"))(1, 2, 3, 4) == 4321  # bytearray, ...
    assert servant.calls == [
        ("print", (5,)),
        ("lambda", ("four",)),
        ("None", (1, 2, 3, 4, 5)),
        ("sum", (1, 2, 3, 4)),
    ]
    k._set_pass(8)
    assert k._get_pass() == 8 and k._get_def() == 99
    # keyword-escaped parameters can be passed by name
    assert getattr(k, _method(Rpc.Keywords, "print"))(_from=6) is None
    others = list(inspect.signature(Rpc.Keywords._None).parameters)[3:]  # bytes, list, len
    assert k._None(_class=1, _self=2, **dict.fromkeys(others, 0)) == 21


def test_print_is_escaped_as_the_design_says(gen: SimpleNamespace) -> None:
    assert "_print" in vars(gen.Rpc.Keywords)
    assert "print" not in vars(gen.Rpc.Keywords)


# =============================================================================================
# values that do not fit: BAD_PARAM on the client, nothing sent
# =============================================================================================


def _bad_values(Rpc: Any) -> list[tuple[str, Callable[[Any], Any]]]:
    P, S = Rpc.Point, Rpc.Shape
    ok = (0, 0, 0, 0, 0, 0, 0.0, 0.0, False, "a", 0)

    def prims(i: int, v: Any) -> Callable[[Any], Any]:
        return lambda s: s.prims(*ok[:i], v, *ok[i + 1 :])

    return [
        ("string over its bound", lambda s: s.bounded("abcdef", [])),
        ("utf-8 string over its bound", lambda s: s.bounded("ééé", [])),
        ("sequence over its bound", lambda s: s.bounded("ab", [1, 2, 3, 4])),
        ("long too big", lambda s: s.set_value(2**31)),
        ("long too small", lambda s: s.set_value(-(2**31) - 1)),
        ("long given a str", lambda s: s.set_value("7")),
        ("long given a float", lambda s: s.set_value(1.5)),
        ("long given None", lambda s: s.set_value(None)),
        ("short too big", prims(0, 2**15)),
        ("unsigned short negative", prims(1, -1)),
        ("unsigned long too big", prims(3, 2**32)),
        ("long long too big", prims(4, 2**63)),
        ("unsigned long long negative", prims(5, -1)),
        ("float overflow", prims(6, 1e39)),
        ("double given a str", prims(7, "1.0")),
        ("char of two characters", prims(9, "ab")),
        ("char outside Latin-1", prims(9, "€")),
        ("octet too big", prims(10, 256)),
        ("octets given a str", lambda s: s.blob("text")),
        ("string given bytes", lambda s: s.inout_string(b"bytes")),
        ("string with NUL", lambda s: s.inout_string("a\0b")),
        ("struct member out of range", lambda s: s.inout_struct(P(0, 2**31))),
        ("struct given None", lambda s: s.inout_struct(None)),
        ("sequence element out of range", lambda s: s.inout_seq([1, 2**31])),
        ("sequence element of the wrong type", lambda s: s.inout_seq([1, "2"])),
        ("union branch of the wrong type", lambda s: s.inout_union(S(name=5))),
        ("union branch out of range", lambda s: s.inout_union(S(count=2**31))),
        ("enum negative", lambda s: s.inout_enum(-1)),
        (
            "sequence of structs, element out of range",
            lambda s: s.mixed(P(), [P(0, 2**40)], "t", 0),
        ),
        ("inout octet too big", lambda s: s.mixed(P(), [], "t", 256)),
        ("attribute of the wrong type", lambda s: s._set_label(5)),
        ("oneway argument out of range", lambda s: s.fire(2**31)),
    ]


def test_values_that_do_not_fit_are_bad_param_before_sending(
    gen: SimpleNamespace, inv: CountingInvoker
) -> None:
    failures = []
    for what, call in _bad_values(gen.Rpc):
        servant = gen.impl.Modes()
        stub = inv.stub(gen.Rpc.Modes, servant)
        inv.sent.clear()
        try:
            call(stub)
        except BAD_PARAM as exc:
            if exc.completed is not NO or inv.sent or servant.calls:
                failures.append(f"{what}: completed={exc.completed.name}, sent={inv.sent}")
        except Exception as exc:
            failures.append(f"{what}: {type(exc).__name__}: {exc}")
        else:
            failures.append(f"{what}: accepted, servant got {servant.calls}")
    assert not failures, "\n".join(failures)


def test_enum_out_of_range_is_bad_param_before_sending(
    modes: tuple[Any, Any], inv: CountingInvoker
) -> None:
    stub, servant = modes
    with pytest.raises(BAD_PARAM):
        stub.pick(3)
    assert not inv.sent and not servant.calls
