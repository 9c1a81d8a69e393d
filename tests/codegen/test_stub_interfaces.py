"""Oneway operations, attributes, interface inheritance (with a diamond) and abstract
enforcement of generated skeletons."""

from __future__ import annotations

import inspect
import threading
from types import SimpleNamespace
from typing import Any

import pytest
from stub_support import CountingInvoker

from miro_gen.exceptions import (
    TIMEOUT,
)

# =============================================================================================
# oneway
# =============================================================================================


def test_oneway_runs_the_servant_and_returns_none(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.fire(5) is None
    assert servant.fired.wait(30)
    assert servant.called("fire") == [(5,)]


def test_oneway_returns_even_if_the_servant_raises(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    for exc in (ZeroDivisionError("x"), TIMEOUT("t"), NotImplementedError()):
        servant.fired.clear()
        servant.exc = exc
        assert stub.fire(1) is None
        assert servant.fired.wait(30)
    servant.exc = None
    assert stub.get_value() == 0  # and the next call is served


def test_oneway_sends_without_asking_for_a_reply(
    modes: tuple[Any, Any], inv: CountingInvoker
) -> None:
    stub, _ = modes
    stub.fire(3)
    stub.nothing()
    assert [(op, oneway) for op, _, oneway in inv.sent] == [("fire", True), ("nothing", False)]


def test_oneway_does_not_wait_for_the_servant(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    servant.gate = threading.Event()  # the servant blocks in fire() until this is set
    try:
        stub.fire(1)
        # The call has returned; the servant is, or will be, held at the gate until now.
        assert not servant.fired.is_set(), "the oneway call waited for the servant"
    finally:
        servant.gate.set()
    assert servant.fired.wait(30)
    assert servant.called("fire") == [(1,)]


# =============================================================================================
# attributes
# =============================================================================================


def test_readonly_attribute_has_only_a_getter(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, _ = modes
    assert hasattr(gen.Rpc.Modes, "_get_counter")
    assert not hasattr(gen.Rpc.Modes, "_set_counter")
    assert not hasattr(gen.POA.Modes, "_set_counter")
    assert "_set_counter" not in gen.POA.Modes._dispatch
    assert not hasattr(gen.Rpc.Modes, "counter")  # no Python property: accessors only
    assert stub._get_counter() == 0
    stub.set_value(1)
    stub.set_value(2)
    assert stub._get_counter() == 2


def test_read_write_attribute(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert {"_get_label", "_set_label"} <= set(gen.POA.Modes._dispatch)
    assert stub._get_label() == "initial"
    assert stub._set_label("renamed ✓") is None
    assert servant.label == "renamed ✓"
    assert stub._get_label() == "renamed ✓"
    assert list(inspect.signature(stub._set_label).parameters) == ["value"]


# =============================================================================================
# inheritance
# =============================================================================================


def test_derived_stub_has_the_base_operations(gen: SimpleNamespace) -> None:
    Rpc = gen.Rpc
    assert issubclass(Rpc.Left, Rpc.Base) and issubclass(Rpc.Right, Rpc.Base)
    assert issubclass(Rpc.Diamond, Rpc.Left) and issubclass(Rpc.Diamond, Rpc.Right)
    for name in (
        "base_op",
        "_get_base_attr",
        "_set_base_attr",
        "left_op",
        "right_op",
        "diamond_op",
    ):
        assert callable(getattr(Rpc.Diamond, name)), name
    assert not hasattr(Rpc.Left, "right_op")


def test_derived_skeleton_dispatches_the_base_operations(gen: SimpleNamespace) -> None:
    POA = gen.POA
    assert issubclass(POA.Diamond, POA.Left) and issubclass(POA.Diamond, POA.Right)
    assert set(POA.Diamond._dispatch) == {
        "base_op",
        "_get_base_attr",
        "_set_base_attr",
        "left_op",
        "right_op",
        "diamond_op",
    }
    assert set(POA.Left._dispatch) == {"base_op", "_get_base_attr", "_set_base_attr", "left_op"}
    assert set(POA.Base._dispatch) == {"base_op", "_get_base_attr", "_set_base_attr"}


def test_diamond_through_every_stub(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc = gen.Rpc
    servant = gen.impl.Diamond()
    stub = inv.stub(Rpc.Diamond, servant)
    assert stub._ref.repo_id == "IDL:Rpc/Diamond:1.0"
    assert stub.base_op(4) == 40
    assert (stub.left_op(), stub.right_op(), stub.diamond_op()) == ("left", "right", "diamond")
    stub._set_base_attr(-8)
    assert stub._get_base_attr() == -8 and servant.attr == -8
    # stubs of the bases on the same object
    for cls in (Rpc.Base, Rpc.Left, Rpc.Right):
        view = inv.stub(cls, servant)
        assert view.base_op(1) == 10
        assert view._get_base_attr() == -8
    assert inv.stub(Rpc.Left, servant).left_op() == "left"
    assert inv.stub(Rpc.Right, servant).right_op() == "right"


# =============================================================================================
# abstract enforcement
# =============================================================================================

MODES_OPERATIONS = {
    "nothing",
    "set_value",
    "get_value",
    "out_only",
    "result_and_outs",
    "two_outs",
    "inout_only",
    "inout_struct",
    "inout_seq",
    "inout_string",
    "inout_enum",
    "inout_union",
    "mixed",
    "prims",
    "blob",
    "bounded",
    "pick",
    "raise_it",
    "no_raises",
    "fire",
    "_get_counter",
    "_get_label",
    "_set_label",
}


def test_skeleton_declares_every_operation_abstract(gen: SimpleNamespace) -> None:
    assert set(gen.POA.Modes.__abstractmethods__) == MODES_OPERATIONS
    assert set(gen.POA.Modes._dispatch) == MODES_OPERATIONS
    assert set(gen.POA.Diamond.__abstractmethods__) == {
        "base_op",
        "_get_base_attr",
        "_set_base_attr",
        "left_op",
        "right_op",
        "diamond_op",
    }
    with pytest.raises(TypeError):
        gen.POA.Modes()


@pytest.mark.parametrize("missing", sorted(MODES_OPERATIONS))
def test_servant_missing_an_operation_cannot_be_instantiated(
    gen: SimpleNamespace, missing: str
) -> None:
    body = {name: (lambda self, *args: None) for name in MODES_OPERATIONS - {missing}}
    Incomplete = type("Incomplete", (gen.POA.Modes,), body)
    with pytest.raises(TypeError, match=missing):
        Incomplete()


@pytest.mark.parametrize("missing", ["base_op", "_set_base_attr", "left_op", "diamond_op"])
def test_diamond_servant_must_implement_inherited_operations(
    gen: SimpleNamespace, missing: str
) -> None:
    names = {"base_op", "_get_base_attr", "_set_base_attr", "left_op", "right_op", "diamond_op"}
    body = {name: (lambda self, *args: None) for name in names - {missing}}
    Incomplete = type("Incomplete", (gen.POA.Diamond,), body)
    with pytest.raises(TypeError, match=missing):
        Incomplete()
