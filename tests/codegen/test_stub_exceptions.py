"""What a client of a generated stub sees of user and system exceptions and of a servant's
failures; unknown operations and objects; what the servant does wrong."""

from __future__ import annotations

import struct
from types import SimpleNamespace
from typing import Any

import pytest
from stub_support import HEADER, MAYBE, NO, YES, CountingInvoker, reply_of

from miro_gen.exceptions import (
    BAD_OPERATION,
    BAD_PARAM,
    COMM_FAILURE,
    MARSHAL,
    NO_IMPLEMENT,
    OBJECT_NOT_EXIST,
    TIMEOUT,
    TRANSIENT,
    UNKNOWN,
    CompletionStatus,
    SystemException,
    UserException,
)
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Reply, ReplyStatus

# =============================================================================================
# exceptions
# =============================================================================================


def test_declared_user_exception_arrives_with_its_fields(
    gen: SimpleNamespace, modes: tuple[Any, Any]
) -> None:
    stub, _ = modes
    with pytest.raises(gen.Rpc.Failed) as info:
        stub.raise_it(1)
    exc = info.value
    assert type(exc) is gen.Rpc.Failed and isinstance(exc, UserException)
    assert (exc.reason, exc.code) == ("boom", 7)
    text = str(exc)
    assert "Failed" in text and "boom" in text and "7" in text, text


def test_declared_user_exception_without_fields(
    gen: SimpleNamespace, modes: tuple[Any, Any]
) -> None:
    stub, _ = modes
    with pytest.raises(gen.Rpc.Empty) as info:
        stub.raise_it(2)
    assert "Empty" in str(info.value)
    stub.raise_it(0)  # and no exception at all when the servant raises none


def test_undeclared_user_exception_is_unknown(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    with pytest.raises(UNKNOWN) as info:
        stub.raise_it(3)  # raises Rpc::Undeclared, which raise_it does not declare
    assert "IDL:Rpc/Undeclared:1.0" in info.value.message
    assert info.value.completed is YES
    assert servant.called("raise_it") == [(3,)]


def test_exception_declared_elsewhere_is_unknown(
    gen: SimpleNamespace, modes: tuple[Any, Any]
) -> None:
    stub, servant = modes
    servant.exc = gen.Rpc.Failed(reason="not here", code=1)
    with pytest.raises(UNKNOWN) as info:
        stub.no_raises(0)
    assert "IDL:Rpc/Failed:1.0" in info.value.message
    assert not isinstance(info.value, gen.Rpc.Failed)


@pytest.mark.parametrize(
    "cls",
    [
        TRANSIENT,
        COMM_FAILURE,
        TIMEOUT,
        MARSHAL,
        OBJECT_NOT_EXIST,
        BAD_OPERATION,
        BAD_PARAM,
        NO_IMPLEMENT,
        UNKNOWN,
    ],
)
@pytest.mark.parametrize("completed", [YES, NO, MAYBE])
def test_system_exception_from_servant_arrives_as_is(
    modes: tuple[Any, Any], cls: type[SystemException], completed: CompletionStatus
) -> None:
    stub, servant = modes
    servant.exc = cls("the servant says ünïcode", 17, completed)
    with pytest.raises(cls) as info:
        stub.no_raises(0)
    exc = info.value
    assert type(exc) is cls
    assert exc.message == "the servant says ünïcode"
    assert exc.minor == 17
    assert exc.completed is completed
    assert cls.__name__ in str(exc) and "the servant says" in str(exc)


def test_system_exception_also_from_an_operation_with_raises(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    servant.exc = TIMEOUT("slow", completed=MAYBE)
    with pytest.raises(TIMEOUT) as info:
        stub.raise_it(9)
    assert info.value.completed is MAYBE


def test_python_exception_in_servant_is_unknown_and_server_keeps_serving(
    modes: tuple[Any, Any],
) -> None:
    stub, servant = modes
    servant.exc = ZeroDivisionError("division by zero in the servant")
    with pytest.raises(UNKNOWN) as info:
        stub.no_raises(0)
    assert info.value.completed is MAYBE
    assert "ZeroDivisionError" in info.value.message
    assert "division by zero in the servant" in info.value.message
    servant.exc = KeyError("k")
    with pytest.raises(UNKNOWN):
        stub.no_raises(0)
    servant.exc = None
    stub.no_raises(0)
    assert stub.result_and_outs(1) == (2, 2, "<1>")


def test_not_implemented_error_is_no_implement(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    servant.exc = NotImplementedError("later")
    with pytest.raises(NO_IMPLEMENT) as info:
        stub.no_raises(0)
    assert info.value.completed is NO
    assert "later" in info.value.message and "no_raises" in info.value.message


def test_servant_deferring_to_the_skeleton_is_no_implement(
    gen: SimpleNamespace, inv: CountingInvoker
) -> None:
    """A servant whose method calls the skeleton's (abstract) one: NO_IMPLEMENT, not a None
    result that fails to encode."""

    class Deferring(gen.impl.Modes):
        def get_value(self) -> int:
            return super(gen.impl.Modes, self).get_value()

    stub = inv.stub(gen.Rpc.Modes, Deferring())
    with pytest.raises(NO_IMPLEMENT) as info:
        stub.get_value()
    assert "get_value" in info.value.message


def test_unknown_operation_is_bad_operation(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    servant = gen.impl.Right()
    stub = inv.stub(gen.Rpc.Right, servant)
    with pytest.raises(BAD_OPERATION) as info:
        stub._call("no_such_operation", HEADER)
    assert "no_such_operation" in info.value.message
    assert info.value.completed is NO
    # a stub of another interface on this object: left_op is not Right's
    left = gen.Rpc.Left(stub._ref, inv)
    assert left.base_op(2) == 20  # the common base works
    with pytest.raises(BAD_OPERATION):
        left.left_op()
    reply = servant._invoke("left_op", HEADER, inv)
    assert reply.status == ReplyStatus.SYSTEM_EXCEPTION
    assert reply.repo_id == BAD_OPERATION._repo_id


def test_unregistered_key_is_object_not_exist(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    stub = gen.Rpc.Modes(ObjectRef("IDL:Rpc/Modes:1.0", inv.endpoint, b"no-such-key"), inv)
    with pytest.raises(OBJECT_NOT_EXIST) as info:
        stub.nothing()
    assert "no-such-key" in info.value.message
    elsewhere = gen.Rpc.Modes(ObjectRef("IDL:Rpc/Modes:1.0", "inproc://other", b"obj1"), inv)
    inv.register(gen.impl.Modes(), b"obj1")
    with pytest.raises(OBJECT_NOT_EXIST):
        elsewhere.nothing()  # the key exists, but at another endpoint


# =============================================================================================
# what the servant does wrong
# =============================================================================================


def test_servant_returning_a_value_of_the_wrong_type(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    servant.bad_two_outs = (1, 2)  # b should be a string
    with pytest.raises(SystemException) as info:
        stub.two_outs()
    assert isinstance(info.value, BAD_PARAM | MARSHAL | UNKNOWN)
    servant.bad_two_outs = 7  # not even a tuple
    with pytest.raises(SystemException):
        stub.two_outs()
    servant.bad_two_outs = None
    assert stub.two_outs() == (-5, "two")  # the server keeps serving


def test_servant_result_that_does_not_encode_is_not_reported_as_not_run(
    modes: tuple[Any, Any],
) -> None:
    stub, servant = modes
    servant.bad_two_outs = (1, 2)
    with pytest.raises(SystemException) as info:
        stub.two_outs()
    assert servant.called("two_outs") == [()]  # the servant ran
    assert info.value.completed is not NO


@pytest.mark.parametrize("case", ["bare UserException", "unencodable fields", "bad message"])
def test_invoke_always_replies_whatever_the_servant_raises(
    gen: SimpleNamespace, inv: CountingInvoker, case: str
) -> None:
    servant = gen.impl.Modes()
    servant.exc = {
        "bare UserException": UserException("not generated"),
        "unencodable fields": gen.Rpc.Failed(reason=123, code="x"),
        "bad message": TIMEOUT(123),
    }[case]
    got = reply_of(servant, "raise_it", HEADER + struct.pack("<i", 9), inv)
    assert isinstance(got, Reply), f"_invoke raised {type(got).__name__}: {got}"
    assert got.status == ReplyStatus.SYSTEM_EXCEPTION
