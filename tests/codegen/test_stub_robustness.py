"""Malformed requests (a MARSHAL reply, the servant not called) and many threads on one stub."""

from __future__ import annotations

import random
import struct
import threading
from types import SimpleNamespace
from typing import Any

import pytest
from stub_support import HEADER, NO, CountingInvoker, reply_of

from miro_gen.exceptions import (
    BAD_PARAM,
    MARSHAL,
    SystemException,
)
from miro_gen.runtime.rpc import LocalInvoker, Reply, ReplyStatus

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
            got = reply_of(servant, op, body[:n], inv)
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
    got = reply_of(servant, op, body, inv)
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
        got = reply_of(servant, op, bytes(data), inv)
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
