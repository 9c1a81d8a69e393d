"""Generated stubs and skeletons, called in process through `LocalInvoker` (real CDR bytes).

`tests/rpc/Rpc.idl` is compiled by `python -m miro_gen.cli.idl` into a temporary folder once per
session and imported from there. Covered: every parameter mode and return convention, user and
system exceptions and what the client sees of a servant's failures, oneway operations,
attributes, interface inheritance (with a diamond), abstract enforcement, object references
(stubs, local servants, nil, `Object`, sequences of references), names that are Python keywords
or builtins, values refused on the client before anything is sent, malformed requests, many
threads on one stub, and the generated code under `mypy --strict`.
"""

from __future__ import annotations

import importlib
import inspect
import keyword
import os
import random
import struct
import subprocess
import sys
import threading
from array import array
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

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
from miro_gen.runtime.rpc import LocalInvoker, Reply, ReplyStatus, Servant, Stub

ROOT = Path(__file__).resolve().parents[1]
IDL = "tests/rpc/Rpc.idl"
PACKAGES = ("Rpc", "Rpc__POA")
HEADER = b"\x00\x01\x00\x00"  # CDR little-endian encapsulation

YES, NO, MAYBE = CompletionStatus.YES, CompletionStatus.NO, CompletionStatus.MAYBE


# =============================================================================================
# generation, servants, fixtures
# =============================================================================================


def _drop_generated_modules() -> None:
    for name in [m for m in sys.modules if m.split(".")[0] in PACKAGES]:
        del sys.modules[name]


@pytest.fixture(scope="session")
def gen(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SimpleNamespace]:
    """The generated packages `Rpc` and `Rpc__POA`, imported from a temporary folder."""
    out = tmp_path_factory.mktemp("rpc_generated")
    proc = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.idl", "-o", str(out), IDL],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert (out / "Rpc" / "__init__.py").is_file() and (out / "Rpc__POA" / "__init__.py").is_file()
    clash = [m for m in sys.modules if m.split(".")[0] in PACKAGES]
    assert not clash, f"modules {clash} are already imported from elsewhere"
    sys.path.insert(0, str(out))
    try:
        importlib.invalidate_caches()
        rpc = importlib.import_module("Rpc")
        poa = importlib.import_module("Rpc__POA")
        assert Path(rpc.__file__).resolve().parent.parent == out.resolve()
        ns = SimpleNamespace(Rpc=rpc, POA=poa, out=out)
        ns.impl = _servant_classes(rpc, poa)
        yield ns
    finally:
        sys.path.remove(str(out))
        _drop_generated_modules()
        importlib.invalidate_caches()


def _servant_classes(Rpc: Any, POA: Any) -> SimpleNamespace:
    """Implementations of the generated skeletons, recording what they are called with."""

    class ModesImpl(POA.Modes):
        def __init__(self) -> None:
            self.calls: list[tuple[str, tuple[Any, ...]]] = []
            self.value: Any = 0
            self.label = "initial"
            self.counter = 0
            self.exc: BaseException | None = None  # raised by no_raises, raise_it(9), fire
            self.gate: threading.Event | None = None  # fire waits for it
            self.fired = threading.Event()
            self.bad_two_outs: Any = None

        def _record(self, op: str, *args: Any) -> None:
            self.calls.append((op, args))

        def nothing(self) -> None:
            self._record("nothing")

        def set_value(self, v: int) -> None:
            self._record("set_value", v)
            self.value = v
            self.counter += 1

        def get_value(self) -> int:
            return self.value

        def out_only(self) -> int:
            self._record("out_only")
            return 42

        def result_and_outs(self, a: int) -> tuple[int, int, str]:
            self._record("result_and_outs", a)
            return a + 1, 2 * a, f"<{a}>"

        def two_outs(self) -> tuple[int, str]:
            self._record("two_outs")
            if self.bad_two_outs is not None:
                return self.bad_two_outs
            return -5, "two"

        def inout_only(self, s: str) -> tuple[str, str]:
            self._record("inout_only", s)
            return s.upper(), s[::-1]

        def inout_struct(self, p: Any) -> Any:
            self._record("inout_struct", p)
            return Rpc.Point(p.y, -p.x)

        def inout_seq(self, s: list[int]) -> list[int]:
            self._record("inout_seq", s)
            return [*s, sum(s)]

        def inout_string(self, s: str) -> str:
            self._record("inout_string", s)
            return s[::-1] + "!"

        def inout_enum(self, c: Any) -> Any:
            self._record("inout_enum", c)
            return Rpc.Color((c + 1) % 3)

        def inout_union(self, u: Any) -> Any:
            self._record("inout_union", u)
            branch = u._branch()
            if branch == "count":
                return Rpc.Shape(count=u.count + 1)
            if branch == "name":
                return Rpc.Shape(name=u.name + "?")
            return Rpc.Shape(u._d, Rpc.Point(u.where.y, u.where.x))

        def mixed(self, a: Any, s: list[Any], tag: str, o: int) -> Any:
            self._record("mixed", a, s, tag, o)
            color = Rpc.Color.GREEN if tag == "g" else Rpc.Color.BLUE
            return Rpc.Point(a.x + 1, a.y + 1), [*s, a], color, (o + 1) & 0xFF

        def prims(self, *args: Any) -> float:
            self._record("prims", *args)
            return float(args[7]) * 2

        def blob(self, data: bytes) -> bytes:
            self._record("blob", data)
            return data[::-1]

        def bounded(self, s: str, q: list[int]) -> None:
            self._record("bounded", s, q)

        def pick(self, c: Any) -> None:
            self._record("pick", c)

        def raise_it(self, which: int) -> None:
            self._record("raise_it", which)
            if which == 1:
                raise Rpc.Failed(reason="boom", code=7)
            if which == 2:
                raise Rpc.Empty()
            if which == 3:
                raise Rpc.Undeclared(what="surprise")
            if which == 9 and self.exc is not None:
                raise self.exc

        def no_raises(self, which: int) -> None:
            self._record("no_raises", which)
            if self.exc is not None:
                raise self.exc

        def fire(self, v: int) -> None:
            self._record("fire", v)
            if self.gate is not None:
                self.gate.wait(30)  # bounded, so that a stub that waits fails rather than hangs
            self.fired.set()
            if self.exc is not None:
                raise self.exc

        def _get_counter(self) -> int:
            return self.counter

        def _get_label(self) -> str:
            return self.label

        def _set_label(self, value: str) -> None:
            self._record("_set_label", value)
            self.label = value

        def called(self, op: str) -> list[tuple[Any, ...]]:
            return [args for name, args in self.calls if name == op]

    class BaseImpl(POA.Base):
        def __init__(self) -> None:
            self.attr = 0

        def base_op(self, x: int) -> int:
            return x * 10

        def _get_base_attr(self) -> int:
            return self.attr

        def _set_base_attr(self, value: int) -> None:
            self.attr = value

    class RightImpl(BaseImpl, POA.Right):
        def right_op(self) -> str:
            return "right"

    class DiamondImpl(BaseImpl, POA.Diamond):
        def left_op(self) -> str:
            return "left"

        def right_op(self) -> str:
            return "right"

        def diamond_op(self) -> str:
            return "diamond"

    class NodeImpl(POA.Node):
        def __init__(self, name: str) -> None:
            self._name = name
            self._next: Any = None
            self.received: list[Any] = []
            self.children: list[Any] = []

        def name(self) -> str:
            return self._name

        def next(self) -> Any:
            return self._next

        def set_next(self, n: Any) -> None:
            self.received.append(n)
            self._next = n

        def echo_object(self, o: Any) -> Any:
            self.received.append(o)
            return o

        def echo_base(self, b: Any) -> Any:
            self.received.append(b)
            return b

        def make_child(self, name: str) -> Any:
            if not name:
                return None
            child = NodeImpl(name)
            self.children.append(child)
            return child  # a local servant: the skeleton turns it into a reference

        def swap(self, n: Any) -> Any:
            self.received.append(n)
            old, self._next = self._next, n
            return old

        def reverse(self, s: list[Any]) -> list[Any]:
            self.received.append(s)
            return s[::-1]

    class KeywordsImpl(POA.Keywords):
        def __init__(self) -> None:
            self.calls: list[tuple[str, tuple[Any, ...]]] = []
            self.pass_ = 0

        # `print` and `sum` are not Python keywords; define both spellings so that the class
        # is instantiable whichever the generator picks (test_keyword_print_is_escaped...).
        def print(self, from_: int) -> None:
            self.calls.append(("print", (from_,)))

        _print = print

        def sum(self, *args: int) -> int:
            self.calls.append(("sum", args))
            return sum(a * 10**i for i, a in enumerate(args))

        _sum = sum

        def _lambda(self, s: str) -> int:
            self.calls.append(("lambda", (s,)))
            return len(s)

        def _None(self, *args: int) -> int:
            self.calls.append(("None", args))
            return sum(a * 10**i for i, a in enumerate(args))

        def _get_pass(self) -> int:
            return self.pass_

        def _set_pass(self, value: int) -> None:
            self.pass_ = value

        def _get_def(self) -> int:
            return 99

    return SimpleNamespace(
        Modes=ModesImpl,
        Base=BaseImpl,
        Right=RightImpl,
        Diamond=DiamondImpl,
        Node=NodeImpl,
        Keywords=KeywordsImpl,
    )


class CountingInvoker(LocalInvoker):
    """A LocalInvoker that counts and records the requests it is asked to send."""

    def __init__(self) -> None:
        super().__init__()
        self.sent: list[tuple[str, bytes, bool]] = []

    def invoke(
        self,
        ref: ObjectRef,
        operation: str,
        body: bytes,
        *,
        oneway: bool = False,
        timeout: float | None = None,
    ) -> Reply | None:
        self.sent.append((operation, bytes(body), oneway))
        return super().invoke(ref, operation, body, oneway=oneway, timeout=timeout)


@pytest.fixture
def inv() -> CountingInvoker:
    return CountingInvoker()


@pytest.fixture
def modes(gen: SimpleNamespace, inv: CountingInvoker) -> tuple[Any, Any]:
    """(stub, servant) of interface Rpc::Modes."""
    servant = gen.impl.Modes()
    return inv.stub(gen.Rpc.Modes, servant), servant


# =============================================================================================
# parameter modes and return conventions
# =============================================================================================


def test_stub_and_skeleton_classes(gen: SimpleNamespace) -> None:
    Rpc, POA = gen.Rpc, gen.POA
    assert issubclass(Rpc.Modes, Stub) and issubclass(POA.Modes, Servant)
    assert Rpc.Modes._repo_id == POA.Modes._repo_id == "IDL:Rpc/Modes:1.0"
    assert Rpc.Modes.__module__ == "Rpc.Rpc_idl" and POA.Modes.__module__ == "Rpc__POA.Rpc_idl"


def test_void_without_out_returns_none(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.nothing() is None
    assert servant.called("nothing") == [()]


def test_in_parameter_and_single_result(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.set_value(-123456) is None
    assert servant.called("set_value") == [(-123456,)]
    assert stub.get_value() == -123456


def test_single_out_is_returned_alone(modes: tuple[Any, Any]) -> None:
    stub, _ = modes
    assert "v" not in inspect.signature(stub.out_only).parameters  # out: not an argument
    assert stub.out_only() == 42


def test_result_and_outs_are_a_tuple_in_declaration_order(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert list(inspect.signature(stub.result_and_outs).parameters) == ["a"]
    result = stub.result_and_outs(20)
    assert type(result) is tuple
    assert result == (21, 40, "<20>")
    assert servant.called("result_and_outs") == [(20,)]


def test_outs_without_result_are_a_tuple(modes: tuple[Any, Any]) -> None:
    stub, _ = modes
    assert stub.two_outs() == (-5, "two")


def test_result_and_inout_are_a_tuple(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    assert stub.inout_only("abc") == ("ABC", "cba")
    assert servant.called("inout_only") == [("abc",)]


def test_inout_struct(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    Point = gen.Rpc.Point
    sent = Point(3, -(2**31))
    got = stub.inout_struct(sent)
    assert got == Point(-(2**31), -3) and type(got) is Point
    assert servant.called("inout_struct") == [(Point(3, -(2**31)),)]
    assert sent == Point(3, -(2**31))  # the caller's value is not modified in place


@pytest.mark.parametrize("seq", [[], [7], [1, -2, 2**31 - 1, -(2**31) + 5]])
def test_inout_sequence(modes: tuple[Any, Any], seq: list[int]) -> None:
    stub, servant = modes
    got = stub.inout_seq(seq)
    assert got == array("i", [*seq, sum(seq)])  # numbers arrive as array.array
    assert servant.called("inout_seq") == [(array("i", seq),)]


@pytest.mark.parametrize("text", ["", "x", "héllo wörld ✓", "a" * 1000])
def test_inout_string(modes: tuple[Any, Any], text: str) -> None:
    stub, servant = modes
    assert stub.inout_string(text) == text[::-1] + "!"
    assert servant.called("inout_string") == [(text,)]


@pytest.mark.parametrize("ordinal", [0, 1, 2])
def test_inout_enum(gen: SimpleNamespace, modes: tuple[Any, Any], ordinal: int) -> None:
    stub, servant = modes
    Color = gen.Rpc.Color
    got = stub.inout_enum(Color(ordinal))
    assert got is Color((ordinal + 1) % 3)
    (args,) = servant.called("inout_enum")
    assert args[0] is Color(ordinal)  # arrives as the IntEnum member, not a bare int


def test_inout_union_every_branch(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    Shape, Point = gen.Rpc.Shape, gen.Rpc.Point
    assert stub.inout_union(Shape(count=41)) == Shape(count=42)
    assert stub.inout_union(Shape(name="sq")) == Shape(name="sq?")
    got = stub.inout_union(Shape(where=Point(1, 2)))
    assert got == Shape(where=Point(2, 1)) and got.where == Point(2, 1)
    # the default branch with a discriminator of the caller's choosing keeps it
    got = stub.inout_union(Shape(77, Point(5, 6)))
    assert got._d == 77 and got.where == Point(6, 5)
    received = [args[0] for args in servant.called("inout_union")]
    assert received == [
        Shape(count=41),
        Shape(name="sq"),
        Shape(where=Point(1, 2)),
        Shape(77, Point(5, 6)),
    ]


def test_mixed_modes(gen: SimpleNamespace, modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    Point, Color = gen.Rpc.Point, gen.Rpc.Color
    params = inspect.signature(stub.mixed).parameters
    assert list(params) == ["a", "s", "tag", "o"]  # in and inout, in IDL order; no out `c`
    result, seq, color, octet = stub.mixed(Point(1, 2), [Point(9, 9)], "g", 255)
    assert result == Point(2, 3)
    assert seq == [Point(9, 9), Point(1, 2)]
    assert color is Color.GREEN
    assert octet == 0
    assert servant.called("mixed") == [(Point(1, 2), [Point(9, 9)], "g", 255)]


def test_primitives_arrive_exactly(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    args = (
        -(2**15),
        2**16 - 1,
        -(2**31),
        2**32 - 1,
        -(2**63),
        2**64 - 1,
        0.5,
        -1e300,
        True,
        "é",
        255,
    )
    assert stub.prims(*args) == -2e300
    assert servant.called("prims") == [args]
    stub.prims(0, 0, 0, 0, 0, 0, 0.0, 0.0, False, "\0", 0)
    assert servant.called("prims")[1] == (0, 0, 0, 0, 0, 0, 0.0, 0.0, False, "\0", 0)


@pytest.mark.parametrize("data", [b"", b"\x00", bytes(range(256)) * 3])
def test_octet_sequence_is_bytes(modes: tuple[Any, Any], data: bytes) -> None:
    stub, servant = modes
    got = stub.blob(data)
    assert got == data[::-1] and type(got) is bytes
    assert servant.called("blob") == [(data,)]


def test_bounded_values_within_their_bounds(modes: tuple[Any, Any]) -> None:
    stub, servant = modes
    stub.bounded("abcde", [1, 2, 3])
    stub.bounded("", [])
    assert servant.called("bounded") == [("abcde", array("i", [1, 2, 3])), ("", array("i"))]


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


# =============================================================================================
# object references
# =============================================================================================


def test_pass_a_stub(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    a_servant, b_servant = Node("a"), Node("b")
    a, b = inv.stub(Rpc.Node, a_servant), inv.stub(Rpc.Node, b_servant)
    assert a.set_next(b) is None
    (received,) = a_servant.received
    assert type(received) is Rpc.Node  # arrives as a stub, not as the servant
    assert received == b and received._ref == b._ref
    assert received.name() == "b"
    got = a.next()
    assert type(got) is Rpc.Node and got == b
    assert got.name() == "b"


def test_pass_a_local_servant(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    a_servant, c_servant = Node("a"), Node("c")
    a = inv.stub(Rpc.Node, a_servant)
    a.set_next(c_servant)  # the invoker makes a reference for the servant
    (received,) = a_servant.received
    assert type(received) is Rpc.Node and received is not c_servant
    assert received.name() == "c"
    assert received._ref == inv.reference_for(c_servant)
    assert received._ref.repo_id == "IDL:Rpc/Node:1.0"
    a.set_next(c_servant)  # the same servant: the same reference
    assert a_servant.received[1] == received


def test_receive_a_reference_to_a_new_object(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    root_servant = Node("root")
    root = inv.stub(Rpc.Node, root_servant)
    kid = root.make_child("kid")  # the servant returns a local servant
    assert type(kid) is Rpc.Node
    assert kid.name() == "kid"
    kid.set_next(root)
    assert root_servant.children[0].next().name() == "root"
    assert kid.next() == root


def test_nil_references(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    servant = Node("n")
    node = inv.stub(Rpc.Node, servant)
    assert node.next() is None
    node.set_next(None)
    assert servant.received == [None]
    assert node.make_child("") is None
    assert node.echo_object(None) is None
    assert node.echo_base(None) is None
    assert node.swap(None) is None


def test_inout_reference(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    node = inv.stub(Rpc.Node, Node("n"))
    first, second = inv.stub(Rpc.Node, Node("first")), Node("second")
    assert node.swap(first) is None
    old = node.swap(second)
    assert type(old) is Rpc.Node and old == first and old.name() == "first"
    assert node.next().name() == "second"


def test_derived_reference_as_base_parameter(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc = gen.Rpc
    node_servant = gen.impl.Node("n")
    node = inv.stub(Rpc.Node, node_servant)
    diamond = inv.stub(Rpc.Diamond, gen.impl.Diamond())
    got = node.echo_base(diamond)
    (received,) = node_servant.received
    assert type(received) is Rpc.Base  # the declared interface
    assert received._ref.repo_id == "IDL:Rpc/Diamond:1.0"  # the object's own type travels
    assert type(got) is Rpc.Base and got.base_op(2) == 20
    assert got._narrow(Rpc.Diamond).diamond_op() == "diamond"


def test_object_typed_parameter(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc = gen.Rpc
    node_servant = gen.impl.Node("n")
    node = inv.stub(Rpc.Node, node_servant)
    other = inv.stub(Rpc.Node, gen.impl.Node("other"))
    got = node.echo_object(other)
    (received,) = node_servant.received
    assert type(received) is Stub and type(got) is Stub  # Object: the base stub
    assert received == other and got == other
    assert got._ref.repo_id == "IDL:Rpc/Node:1.0"
    assert got._narrow(Rpc.Node).name() == "other"
    # any interface, and a local servant, may be passed as an Object
    diamond = gen.impl.Diamond()
    assert node.echo_object(diamond)._narrow(Rpc.Diamond).diamond_op() == "diamond"


def test_sequence_of_references(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    Rpc, Node = gen.Rpc, gen.impl.Node
    servant = Node("list")
    node = inv.stub(Rpc.Node, servant)
    a, b = inv.stub(Rpc.Node, Node("a")), Node("b")
    got = node.reverse([a, b, None])
    assert [type(x) for x in servant.received[0]] == [Rpc.Node, Rpc.Node, type(None)]
    assert got[0] is None and [x.name() for x in got[1:]] == ["b", "a"]
    assert node.reverse([]) == []


def test_reference_argument_of_the_wrong_kind_is_bad_param(
    gen: SimpleNamespace, inv: CountingInvoker
) -> None:
    node = inv.stub(gen.Rpc.Node, gen.impl.Node("n"))
    sent = len(inv.sent)
    for wrong in (42, "IDL:Rpc/Node:1.0", object()):
        with pytest.raises(BAD_PARAM):
            node.set_next(wrong)
        with pytest.raises(BAD_PARAM):
            node.echo_object(wrong)
    assert len(inv.sent) == sent


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


def _reply_of(servant: Any, op: str, body: bytes, inv: Any) -> Reply | BaseException:
    try:
        return servant._invoke(op, body, inv)
    except BaseException as exc:
        return exc


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
    got = _reply_of(servant, "raise_it", HEADER + struct.pack("<i", 9), inv)
    assert isinstance(got, Reply), f"_invoke raised {type(got).__name__}: {got}"
    assert got.status == ReplyStatus.SYSTEM_EXCEPTION


# =============================================================================================
# malformed requests: a MARSHAL reply, the servant not called
# =============================================================================================


def _valid_requests(gen: SimpleNamespace) -> list[tuple[str, bytes]]:
    """(operation, body) of well-formed requests, as the stubs send them."""
    Rpc = gen.Rpc
    P = Rpc.Point
    inv = CountingInvoker()
    stub = inv.stub(Rpc.Modes, gen.impl.Modes())
    stub.set_value(7)
    stub.result_and_outs(3)
    stub.inout_only("hello")
    stub.inout_struct(P(1, 2))
    stub.inout_seq([1, 2, 3])
    stub.inout_string("wörld")
    stub.inout_enum(Rpc.Color.BLUE)
    stub.inout_union(Rpc.Shape(name="sq"))
    stub.inout_union(Rpc.Shape(where=P(3, 4)))
    stub.mixed(P(1, 2), [P(3, 4), P(5, 6)], "tag", 9)
    stub.prims(1, 2, 3, 4, 5, 6, 7.0, 8.0, True, "c", 9)
    stub.blob(b"\x01\x02\x03")
    stub.bounded("abc", [1, 2])
    stub.pick(Rpc.Color.GREEN)
    stub.raise_it(0)
    stub.fire(1)
    stub._set_label("label")
    node = inv.stub(Rpc.Node, gen.impl.Node("n"))
    node.set_next(node)
    node.reverse([node, None])
    node.make_child("kid")
    return [
        (op, body)
        for op, body, _ in inv.sent
        if op in gen.POA.Modes._dispatch or op in ("set_next", "reverse", "make_child")
    ]


def _servant_for(gen: SimpleNamespace, op: str) -> Any:
    return gen.impl.Modes() if op in gen.POA.Modes._dispatch else gen.impl.Node("n")


def _servant_calls(servant: Any) -> int:
    return len(getattr(servant, "calls", getattr(servant, "received", [])))


def test_every_truncated_request_is_marshal(gen: SimpleNamespace) -> None:
    inv = LocalInvoker()
    failures = []
    for op, body in _valid_requests(gen):
        servant = _servant_for(gen, op)
        inv.register(servant)
        assert servant._invoke(op, body, inv).status == ReplyStatus.OK, op
        before = _servant_calls(servant)
        for n in range(len(body)):
            got = _reply_of(servant, op, body[:n], inv)
            if not (
                isinstance(got, Reply)
                and got.status == ReplyStatus.SYSTEM_EXCEPTION
                and got.repo_id == MARSHAL._repo_id
            ):
                failures.append(f"{op} cut to {n} bytes: {got!r}")
        if _servant_calls(servant) != before:
            failures.append(f"{op}: the servant was called with a truncated request")
    assert not failures, "\n".join(failures)


def _system_exception(reply: Reply) -> SystemException:
    from miro_gen.runtime.rpc import raise_system_exception

    assert reply.status == ReplyStatus.SYSTEM_EXCEPTION
    try:
        raise_system_exception(reply)
    except SystemException as exc:
        return exc
    raise AssertionError("no exception")  # pragma: no cover


def _s(text: bytes) -> bytes:
    """A CDR string (length with the NUL, bytes, NUL) at a 4-aligned position."""
    return struct.pack("<I", len(text) + 1) + text + b"\0"


@pytest.mark.parametrize(
    ("op", "body"),
    [
        ("set_value", b""),
        ("set_value", b"\x00\x01\x00"),
        ("set_value", b"\x00\x07\x00\x00" + b"\0" * 4),  # unknown encapsulation kind
        ("set_value", b"\x01\x01\x00\x00" + b"\0" * 4),
        ("set_value", b"\x00\x07\x00\x00" + b"\0" * 4),
        ("set_value", b"\x00\x09\x00\x00" + b"\0" * 4),  # XCDR2: not what stubs send
        ("inout_enum", HEADER + struct.pack("<I", 3)),  # no such enumerator
        ("inout_enum", HEADER + struct.pack("<I", 2**32 - 1)),
        ("inout_string", HEADER + _s(b"\xff\xfe")),  # not UTF-8
        ("inout_string", HEADER + struct.pack("<I", 3) + b"abc"),  # no NUL
        ("inout_string", HEADER + struct.pack("<I", 2**31)),  # longer than the data
        ("bounded", HEADER + _s(b"abcdefgh") + struct.pack("<I", 0)),  # over the bound
        ("bounded", HEADER + _s(b"ab") + b"\0" + struct.pack("<IIIII", 4, 1, 2, 3, 4)),
        ("inout_seq", HEADER + struct.pack("<I", 2**31 - 1)),  # huge length, no data
        ("blob", HEADER + struct.pack("<I", 2**32 - 1) + b"xyz"),
        ("inout_union", HEADER + struct.pack("<i", 2) + struct.pack("<I", 99) + b"ab"),
        ("mixed", HEADER + struct.pack("<ii", 1, 2) + struct.pack("<I", 10**6)),
        ("_set_label", HEADER + b"\x05\x00"),
    ],
)
def test_malformed_request_is_a_marshal_reply(
    gen: SimpleNamespace, inv: CountingInvoker, op: str, body: bytes
) -> None:
    servant = gen.impl.Modes()
    inv.register(servant)
    got = _reply_of(servant, op, body, inv)
    assert isinstance(got, Reply), f"_invoke raised {type(got).__name__}: {got}"
    exc = _system_exception(got)
    assert type(exc) is MARSHAL, exc
    assert exc.completed is NO
    assert servant.calls == []


def test_big_endian_request_is_accepted(gen: SimpleNamespace, inv: CountingInvoker) -> None:
    servant = gen.impl.Modes()
    inv.register(servant)
    reply = servant._invoke("set_value", b"\x00\x00\x00\x00" + struct.pack(">i", -2), inv)
    assert reply.status == ReplyStatus.OK
    body = b"\x00\x00\x00\x00" + struct.pack(">I", 6) + b"hello\0"
    reply = servant._invoke("inout_string", body, inv)
    assert reply.status == ReplyStatus.OK
    assert servant.calls == [("set_value", (-2,)), ("inout_string", ("hello",))]


def test_random_corruption_never_escapes_invoke(gen: SimpleNamespace) -> None:
    rng = random.Random(20240611)
    inv = LocalInvoker()
    requests = _valid_requests(gen)
    failures = []
    # BAD_PARAM: what the servant computes from a corrupted argument may not encode (an
    # overflowing long); MARSHAL: the request does not decode
    allowed = {MARSHAL._repo_id, BAD_PARAM._repo_id}
    for i in range(3000):
        op, body = requests[i % len(requests)]
        data = bytearray(body)
        for _ in range(rng.randint(1, 3)):
            kind = rng.random()
            if kind < 0.6 and len(data) > 4:
                data[rng.randrange(4, len(data))] = rng.randrange(256)
            elif kind < 0.8 and data:
                del data[rng.randrange(len(data)) :]
            else:
                data += bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        servant = _servant_for(gen, op)
        inv.register(servant)
        got = _reply_of(servant, op, bytes(data), inv)
        if not isinstance(got, Reply):
            failures.append(f"{op} {bytes(data).hex()}: raised {type(got).__name__}: {got}")
        elif got.status == ReplyStatus.SYSTEM_EXCEPTION and got.repo_id not in allowed:
            failures.append(f"{op} {bytes(data).hex()}: {got.repo_id} {_system_exception(got)}")
        elif got.status == ReplyStatus.USER_EXCEPTION and op != "raise_it":
            failures.append(f"{op} {bytes(data).hex()}: user exception {got.repo_id}")
    assert not failures, "\n".join(failures[:20])


# =============================================================================================
# concurrency
# =============================================================================================


def test_many_threads_on_one_stub(gen: SimpleNamespace) -> None:
    inv = LocalInvoker()
    servant = gen.impl.Modes()
    stub = inv.stub(gen.Rpc.Modes, servant)
    Point = gen.Rpc.Point
    threads, calls = 8, 200
    start = threading.Barrier(threads)
    errors: list[str] = []

    def worker(t: int) -> None:
        start.wait()
        for i in range(calls):
            a = t * 100_000 + i
            try:
                if (got := stub.result_and_outs(a)) != (a + 1, 2 * a, f"<{a}>"):
                    errors.append(f"thread {t} call {i}: {got}")
                if (p := stub.inout_struct(Point(t, i))) != Point(i, -t):
                    errors.append(f"thread {t} call {i}: {p}")
            except Exception as exc:
                errors.append(f"thread {t} call {i}: {type(exc).__name__}: {exc}")

    pool = [threading.Thread(target=worker, args=(t,)) for t in range(threads)]
    for th in pool:
        th.start()
    for th in pool:
        th.join(60)
    assert not any(th.is_alive() for th in pool)
    assert not errors, "\n".join(errors[:20])
    assert len(servant.called("result_and_outs")) == threads * calls


# =============================================================================================
# static typing: the generated code under mypy --strict
# =============================================================================================

TYPED_USAGE = '''\
"""A servant and a client, written as a user would, for mypy --strict."""

from __future__ import annotations

from array import array
from typing import Any

import numpy
import Rpc
import Rpc__POA
from miro_gen.exceptions import UNKNOWN, CompletionStatus, SystemException
from miro_gen.runtime.rpc import LocalInvoker, Stub


class ModesImpl(Rpc__POA.Modes):
    def __init__(self) -> None:
        self.value = 0
        self.label = ""

    def nothing(self) -> None:
        pass

    def set_value(self, v: int) -> None:
        self.value = v

    def get_value(self) -> int:
        return self.value

    def out_only(self) -> int:
        return 1

    def result_and_outs(self, a: int) -> tuple[int, int, str]:
        return a, 2 * a, str(a)

    def two_outs(self) -> tuple[int, str]:
        return 1, "b"

    def inout_only(self, s: str) -> tuple[str, str]:
        return s, s.upper()

    def inout_struct(self, p: Rpc.Point) -> Rpc.Point:
        return Rpc.Point(p.y, p.x)

    def inout_seq(self, s: Rpc.LongSeq) -> Rpc.LongSeq:
        return s[::-1]

    def inout_string(self, s: str) -> str:
        return s[::-1]

    def inout_enum(self, c: Rpc.Color) -> Rpc.Color:
        return Rpc.Color.BLUE if c is Rpc.Color.RED else c

    def inout_union(self, u: Rpc.Shape) -> Rpc.Shape:
        return Rpc.Shape(count=u.count + 1)

    def mixed(
        self, a: Rpc.Point, s: Rpc.PointSeq, tag: str, o: int
    ) -> tuple[Rpc.Point, Rpc.PointSeq, Rpc.Color, int]:
        return a, [*s, a], Rpc.Color.GREEN, o

    def prims(
        self, s: int, us: int, l: int, ul: int, ll: int, ull: int,
        f: float, d: float, b: bool, ch: str, o: int,
    ) -> float:
        return d + f

    def blob(self, data: bytes) -> bytes:
        return data

    def bounded(self, s: Rpc.Short5, q: Rpc.Seq3) -> None:
        pass

    def pick(self, c: Rpc.Color) -> None:
        pass

    def raise_it(self, which: int) -> None:
        raise Rpc.Failed(reason="r", code=which)

    def no_raises(self, which: int) -> None:
        pass

    def fire(self, v: int) -> None:
        pass

    def _get_counter(self) -> int:
        return 0

    def _get_label(self) -> str:
        return self.label

    def _set_label(self, value: str) -> None:
        self.label = value


class DiamondImpl(Rpc__POA.Diamond):
    def base_op(self, x: int) -> int:
        return x

    def _get_base_attr(self) -> int:
        return 0

    def _set_base_attr(self, value: int) -> None:
        pass

    def left_op(self) -> str:
        return "l"

    def right_op(self) -> str:
        return "r"

    def diamond_op(self) -> str:
        return "d"


class NodeImpl(Rpc__POA.Node):
    def __init__(self) -> None:
        self.following: Rpc.Node | None = None

    def name(self) -> str:
        return "n"

    def next(self) -> Rpc.Node | None:
        return self.following

    def set_next(self, n: Rpc.Node | None) -> None:
        self.following = n

    def echo_object(self, o: Stub | None) -> Stub | None:
        return o

    def echo_base(self, b: Rpc.Base | None) -> Rpc.Base | None:
        return b

    def make_child(self, name: str) -> NodeImpl:  # a servant returned becomes a reference
        return NodeImpl()

    def swap(self, n: Rpc.Node | None) -> Rpc.Node | None:
        return n

    def reverse(self, s: list[Rpc.Node | None]) -> list[Rpc.Node | None]:
        return s[::-1]


def client() -> None:
    inv = LocalInvoker()
    modes: Rpc.Modes = inv.stub(Rpc.Modes, ModesImpl())
    modes.nothing()
    modes.set_value(3)
    value: int = modes.get_value()
    single: int = modes.out_only()
    result, twice, text = modes.result_and_outs(3)
    total: int = result + twice + value + single
    upper: str = text.upper()
    n, b = modes.two_outs()
    r, s = modes.inout_only("x")
    point: Rpc.Point = modes.inout_struct(Rpc.Point(1, 2))
    seq: Rpc.LongSeq = modes.inout_seq([1, 2])
    longs: array[int] = modes.inout_seq((1, 2))  # numbers go as any sequence or buffer
    longs = modes.inout_seq(array("i", longs))
    longs = modes.inout_seq(numpy.arange(3, dtype=numpy.int32))
    view: numpy.ndarray[Any, numpy.dtype[numpy.int32]] = numpy.frombuffer(seq, numpy.int32)
    rev: str = modes.inout_string("abc")
    color: Rpc.Color = modes.inout_enum(Rpc.Color.RED)
    shape: Rpc.Shape = modes.inout_union(Rpc.Shape(count=1))
    res, points, col, octet = modes.mixed(Rpc.Point(), [Rpc.Point(1, 2)], "t", 3)
    first: Rpc.Point = points[0]
    d: float = modes.prims(1, 2, 3, 4, 5, 6, 7.0, 8.0, True, "c", 9)
    raw: bytes = modes.blob(b"ab")
    modes.bounded("abc", [1])
    modes.pick(Rpc.Color.GREEN)
    modes.fire(1)
    modes._set_label("x")
    label: str = modes._get_label()
    counter: int = modes._get_counter()
    try:
        modes.raise_it(1)
    except Rpc.Failed as failed:
        reason: str = failed.reason
        code: int = failed.code
        print(reason, code)
    except UNKNOWN as unknown:
        done: CompletionStatus = unknown.completed
        print(done)
    except SystemException as other:
        print(other.message, other.minor)
    diamond: Rpc.Diamond = inv.stub(Rpc.Diamond, DiamondImpl())
    base: Rpc.Base = diamond
    left: Rpc.Left = diamond
    print(base.base_op(1), left.left_op(), diamond.right_op(), diamond.diamond_op())
    node: Rpc.Node = inv.stub(Rpc.Node, NodeImpl())
    node.set_next(node)
    node.set_next(None)
    node.set_next(NodeImpl())  # a local servant travels as a reference to itself
    nodes: list[Rpc.Node] = [node]
    for reversed_node in node.reverse(nodes):  # any sequence of stubs will do
        print(reversed_node)
    following: Rpc.Node | None = node.next()
    if following is not None:
        print(following.name())
    obj: Stub | None = node.echo_object(node)
    echoed: Rpc.Base | None = node.echo_base(diamond)
    swapped: Rpc.Node | None = node.swap(node)
    print(total, upper, n, b, r, s, point, seq, rev, color, shape, res, col, octet, first, d,
          raw, label, counter, obj, echoed, swapped, longs, view)
'''

TYPE_ERROR_USAGE = """\
import Rpc


def client(modes: Rpc.Modes) -> None:
    modes.set_value("not a number")
"""

SEQUENCE_OF_REFERENCES_USAGE = """\
import Rpc


def client(node: Rpc.Node) -> None:
    for other in node.reverse([node]):
        if other is not None:
            print(other.name())
"""


def _mypy(gen: SimpleNamespace, name: str, text: str) -> subprocess.CompletedProcess[str]:
    pytest.importorskip("mypy")
    folder = gen.out / "typecheck"
    folder.mkdir(exist_ok=True)
    (folder / "mypy.ini").write_text("[mypy]\n")
    path = folder / name
    path.write_text(text)
    # miro_gen's own generated packages (MiroNaming) come from generated/, as in a wheel.
    paths = [str(gen.out), str(ROOT), str(ROOT / "generated")]
    env = {**os.environ, "MYPYPATH": os.pathsep.join(paths)}
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--strict",
            "--python-version",
            "3.11",
            "--config-file",
            str(folder / "mypy.ini"),
            "--cache-dir",
            str(folder / ".mypy_cache"),
            "--no-color-output",
            "--show-error-codes",
            name,
        ],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_generated_code_is_usable_under_mypy_strict(gen: SimpleNamespace) -> None:
    out = _mypy(gen, "typed_usage.py", TYPED_USAGE)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Success" in out.stdout


def test_mypy_reports_a_wrong_argument_type(gen: SimpleNamespace) -> None:
    out = _mypy(gen, "type_error.py", TYPE_ERROR_USAGE)
    assert out.returncode == 1, out.stdout + out.stderr
    errors = [line for line in out.stdout.splitlines() if ": error:" in line]
    assert len(errors) == 1, out.stdout
    assert errors[0].startswith("type_error.py:5:"), errors[0]
    assert '"set_value"' in errors[0] and "[arg-type]" in errors[0], errors[0]


def test_sequence_of_references_is_typed_as_stubs(gen: SimpleNamespace) -> None:
    out = _mypy(gen, "sequence_of_references.py", SEQUENCE_OF_REFERENCES_USAGE)
    assert out.returncode == 0, out.stdout + out.stderr
