"""Remote calls between real processes over ZeroMQ on loopback (no naming service yet)."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import Miro
import Miro__POA
import pytest
import zmq
from loopback import eventually, free_port
from repo_paths import TESTS

from miro_gen.exceptions import COMM_FAILURE, OBJECT_NOT_EXIST, TIMEOUT, TRANSIENT, CompletionStatus
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.rpc.adapter import ObjectAdapter
from miro_gen.transport.rpc.invoker import ZmqInvoker

HERE = TESTS
SERVER = HERE / "procs" / "example_server.py"
REPO_ID = "IDL:Miro/Example:1.0"


class Server:
    def __init__(self, key: str = "ExampleA") -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(SERVER), key], stdout=subprocess.PIPE, text=True
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().split()
        assert line and line[0] == "READY", f"server did not start: {line}"
        self.endpoint = line[1]
        self.ref = ObjectRef(REPO_ID, self.endpoint, key.encode())

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait(10)

    def kill_when_busy(self) -> None:
        """Kill it once its servant has begun a setData(a < 0): the call has reached it (a
        a timer instead may fire, on a loaded machine, before the request has left the caller)."""
        assert self.proc.stdout is not None
        if self.proc.stdout.readline().strip() == "BUSY":
            self.kill()


@pytest.fixture
def server() -> Iterator[Server]:
    s = Server()
    yield s
    s.kill()


@pytest.fixture
def invoker() -> Iterator[ZmqInvoker]:
    inv = ZmqInvoker(zmq.Context())
    yield inv
    inv.close()
    inv.context.term()


def test_set_and_get_data_across_processes(server: Server, invoker: ZmqInvoker) -> None:
    stub = Miro.Example(server.ref, invoker)
    stub.setData(0.0, 10.0)
    assert stub.getData() == Miro.ExampleStructIDL(1.0, 11.0)
    for i in range(100):
        stub.setData(float(i), 2.0 * i)
        assert stub.getData() == Miro.ExampleStructIDL(i + 1.0, 2.0 * i + 1)


def test_calls_from_many_threads(server: Server, invoker: ZmqInvoker) -> None:
    stub = Miro.Example(server.ref, invoker)
    errors: list[BaseException] = []

    def work() -> None:
        try:
            for _ in range(50):
                assert isinstance(stub.getData(), Miro.ExampleStructIDL)
        except BaseException as e:
            errors.append(e)

    threads = [threading.Thread(target=work) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert not errors


def test_unknown_object_is_object_not_exist(server: Server, invoker: ZmqInvoker) -> None:
    stub = Miro.Example(ObjectRef(REPO_ID, server.endpoint, b"nobody"), invoker)
    with pytest.raises(OBJECT_NOT_EXIST):
        stub.getData()


def test_nobody_listening_is_transient_promptly(invoker: ZmqInvoker) -> None:
    stub = Miro.Example(ObjectRef(REPO_ID, f"tcp://127.0.0.1:{free_port()}", b"x"), invoker)
    with pytest.raises(TRANSIENT) as info:
        stub.getData()
    assert info.value.completed is CompletionStatus.NO
    assert "refused" in str(info.value)  # said at once, not after the connect timeout


def test_timeout_then_the_next_call_works(server: Server, invoker: ZmqInvoker) -> None:
    slow = Miro.Example(server.ref, invoker, timeout=0.3)
    with pytest.raises(TIMEOUT) as info:
        slow.setData(-1.0, 0.0)  # the servant sleeps 1 s
    assert info.value.completed is CompletionStatus.MAYBE
    fresh = Miro.Example(server.ref, invoker)
    eventually(lambda: fresh.getData() == Miro.ExampleStructIDL(0.0, 1.0))  # it did finish


def test_server_killed_mid_call_is_comm_failure_then_restart_works(
    invoker: ZmqInvoker,
) -> None:
    first = Server()
    stub = Miro.Example(first.ref, invoker, timeout=30)
    threading.Thread(target=first.kill_when_busy, daemon=True).start()
    with pytest.raises(COMM_FAILURE) as info:
        stub.setData(-20.0, 0.0)  # would sleep 20 s, more than the heartbeats' time to notice
    assert info.value.completed is CompletionStatus.MAYBE
    with pytest.raises(TRANSIENT):
        stub.getData()  # nobody there now
    second = Server()
    try:
        again = Miro.Example(second.ref, invoker)
        assert again.getData() == Miro.ExampleStructIDL(1.0, 1.0)
    finally:
        second.kill()


def test_malformed_frames_are_dropped_and_the_server_goes_on(
    server: Server, invoker: ZmqInvoker
) -> None:
    ctx = zmq.Context.instance()
    rogue = ctx.socket(zmq.DEALER)
    rogue.setsockopt(zmq.LINGER, 0)
    rogue.connect(server.endpoint)
    for parts in ([b"garbage"], [b"\x09" * 30, b"x"], [b"\x01\x01" + bytes(30), b""], [b""] * 5):
        rogue.send_multipart(parts)
    good_header_bad_body = [
        bytes.fromhex("01010000")
        + bytes(4)
        + (1).to_bytes(8, "little")
        + b"\x08\x00ExampleA"
        + b"\x07\x00setData",
        b"\x00\x01\x00\x00\x01",
    ]
    rogue.send_multipart(good_header_bad_body)
    assert rogue.poll(5000)
    header, _ = rogue.recv_multipart()
    assert header[2] == 2  # system exception
    assert b"MARSHAL" in header
    rogue.close()
    assert Miro.Example(server.ref, invoker).getData() == Miro.ExampleStructIDL(1.0, 1.0)


class Blocking(Miro__POA.Example):
    """setData(a, b) waits for `release` (or `a` seconds when a > 0); getData answers at once,
    marked @nonblocking when `quick`. Counts the setData calls that ran."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.ran = 0

    def setData(self, a: float, b: float) -> None:
        self.ran += 1
        if a > 0:
            time.sleep(a)
        else:
            self.release.wait(30)

    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(float(self.ran), 0.0)


@contextlib.contextmanager
def in_process_server(servant: Miro__POA.Example, workers: int = 16) -> Iterator[Miro.Example]:
    """`servant` on an adapter of this process (no reactor running), and a stub of it."""
    reactor = Reactor(zmq.Context())
    inv = ZmqInvoker(reactor.context)
    adapter = ObjectAdapter(reactor, inv, workers=workers)
    try:
        yield Miro.Example(adapter.activate(servant), inv)
    finally:
        adapter.close()
        reactor.close()
        inv.close()


def test_a_servant_that_blocks_does_not_stop_the_server() -> None:
    """The thread that received setData runs it and blocks; another takes over the socket.
    The second time, setData is known to block and is handed over before it runs."""
    servant = Blocking()
    with in_process_server(servant) as stub:
        for round_ in (1, 2):
            servant.release.clear()
            blocked = threading.Thread(target=stub.setData, args=(0.0, 0.0))
            blocked.start()
            eventually(lambda: servant.ran == round_)  # noqa: B023 - waited for at once
            for _ in range(3):
                assert stub.getData() == Miro.ExampleStructIDL(float(round_), 0.0)
            assert blocked.is_alive()
            servant.release.set()
            blocked.join(10)
            assert not blocked.is_alive()


def test_requests_wait_for_a_free_worker_and_late_ones_are_not_run() -> None:
    """With one worker busy, a second call waits in the queue; its caller gives up before the
    worker is free, so it never runs. Other calls are answered meanwhile."""
    servant = Blocking()
    with in_process_server(servant, workers=1) as stub:
        first = threading.Thread(target=stub.setData, args=(0.0, 0.0))
        first.start()
        eventually(lambda: servant.ran == 1)
        impatient = Miro.Example(stub._ref, stub._invoker, timeout=0.3)
        with pytest.raises(TIMEOUT):
            impatient.setData(0.0, 0.0)  # queued behind the first
        # The server counts the caller's 0.3 s from when it got the call, a little later than
        # the caller: be sure, with a margin a loaded machine will not eat.
        time.sleep(1.0)
        servant.release.set()
        first.join(10)
        assert stub.getData() == Miro.ExampleStructIDL(1.0, 0.0)  # the late one did not run


def test_a_nonblocking_method_of_the_server_process(server: Server, invoker: ZmqInvoker) -> None:
    stub = Miro.Example(ObjectRef(REPO_ID, server.endpoint, b"Quick"), invoker)
    stub.setData(4.0, 5.0)
    assert stub.getData() == Miro.ExampleStructIDL(5.0, 6.0)


def test_a_stub_without_a_time_limit_waits_for_its_reply(
    server: Server, invoker: ZmqInvoker
) -> None:
    patient = Miro.Example(server.ref, invoker, timeout=0)  # 0: no limit
    patient.setData(-0.2, 5.0)  # the servant sleeps 0.2 s
    assert patient.getData() == Miro.ExampleStructIDL(-0.2 + 1, 6.0)
