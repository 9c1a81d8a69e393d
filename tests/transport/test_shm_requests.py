"""Large request bodies through the caller's shared memory (transport.rpc.shared,
`SharedRequests`): a real server process (tests/procs/body_server.py) that answers each
request with its body's CRC-32 and length, callers in this process and in processes of their
own. A body read while it was rewritten, or shifted, would not match its CRC."""

from __future__ import annotations

import os
import random
import signal
import struct
import subprocess
import sys
import zlib
from typing import Any

import pytest
import zmq
from loopback import dev_shm, eventually, service_env
from repo_paths import TESTS

from miro_gen.exceptions import MARSHAL, CompletionStatus
from miro_gen.runtime.cdr import HEADER_LE, ObjectRef
from miro_gen.runtime.rpc import Reply, ReplyStatus, raise_system_exception
from miro_gen.transport import shm
from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.invoker import ZmqInvoker
from miro_gen.transport.rpc.shared import UNREADABLE_MINOR, BodyPool, caller_marker

pytestmark = pytest.mark.skipif(not shm.available(), reason="shared memory needs Linux memfd")

MIB = 1 << 20
PAIR = struct.Struct("<II")


class BodyProcess:
    """tests/procs/body_server.py in a process of its own."""

    def __init__(self, **env: str) -> None:
        self.p = subprocess.Popen(
            [sys.executable, str(TESTS / "procs" / "body_server.py")],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(**{"MIRO_SHM": "1", **env}),
        )
        assert self.p.stdout is not None
        line = self.p.stdout.readline().split()
        assert line and line[0] == "READY", f"server did not start: {line}"
        self.endpoint, self.pid = line[1], int(line[2])

    def ref(self) -> ObjectRef:
        return ObjectRef("IDL:Test/Body:1.0", self.endpoint, b"Body")

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGKILL)
        self.p.wait(10)


def pair_of(reply: Reply | None) -> tuple[int, int]:
    assert reply is not None
    if reply.status is not ReplyStatus.OK:
        raise_system_exception(reply)
    return PAIR.unpack_from(reply.body, 4)


def crc_call(invoker: ZmqInvoker, server: BodyProcess, body: bytes, op: str = "crc") -> None:
    """A call whose body comes back as its CRC-32 and length, checked."""
    assert pair_of(invoker.invoke(server.ref(), op, body)) == (zlib.crc32(body), len(body))


def stats(invoker: ZmqInvoker, server: BodyProcess) -> tuple[int, int]:
    """(bodies the server read from callers' shared memory, bodies it could not read)."""
    return pair_of(invoker.invoke(server.ref(), "stats", HEADER_LE))


def request_pools(pid: int) -> set[str]:
    """The callers' pools of requests a process maps (one inode each)."""
    with open(f"/proc/{pid}/maps") as f:
        return {line.split()[4] for line in f if "miro-requests" in line}


def body_of(size: int, seed: int) -> bytes:
    return random.Random(seed).randbytes(size)


@pytest.mark.parametrize("size", [shm.THRESHOLD - 1, shm.THRESHOLD, shm.THRESHOLD + 1, MIB])
def test_requests_from_the_threshold_on_go_through_the_callers_pool_whole(
    invoker: ZmqInvoker, size: int
) -> None:
    """Below the threshold in the frame; at and above it, once the caller has heard the server
    takes them (its first reply), through the caller's pool: every body arrives whole."""
    before = dev_shm()
    server = BodyProcess()
    try:
        assert stats(invoker, server) == (0, 0)  # the first reply: the server takes them
        for seed in range(3):
            crc_call(invoker, server, body_of(size, seed))
        crc_call(invoker, server, body_of(size, 9), "slow_crc")  # another thread replies
        shared = 4 if size >= shm.THRESHOLD else 0
        assert stats(invoker, server) == (shared, 0)
        assert (invoker.requests.shared if invoker.requests else 0) == shared
        assert bool(request_pools(server.pid)) == (size >= shm.THRESHOLD)
    finally:
        server.kill()
    assert dev_shm() == before  # memfds: never a file


def test_an_exhausted_pool_sends_requests_in_frames(
    invoker: ZmqInvoker, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MIRO_SHM_CALL_SLOTS", "2")
    monkeypatch.setenv("MIRO_SHM_LEASE", "3600")
    server = BodyProcess()
    try:
        stats(invoker, server)
        for seed in range(2):  # two requests' slots nobody gives back
            assert invoker._put_request(body_of(shm.THRESHOLD, seed), MIB) is not None
        for seed in range(3):  # no free slot: in frames, never a wait
            crc_call(invoker, server, body_of(MIB, seed))
        assert invoker.requests is not None and invoker.requests.framed == 3
        assert stats(invoker, server) == (0, 0)
    finally:
        server.kill()


def test_a_server_that_cannot_read_a_request_body_refuses_it_and_it_goes_again_in_frames(
    invoker: ZmqInvoker,
) -> None:
    """A server with shared memory off (as one that cannot map the caller's memory) answers
    MARSHAL, completed NO: the call did not run; the invoker sends it again in frames and
    keeps to frames for that server."""
    server = BodyProcess(MIRO_SHM="0")
    try:
        stats(invoker, server)
        conn = invoker._local.conns[server.endpoint]
        assert conn.takes_requests is False  # it does not say it takes them
        conn.takes_requests = True  # as if it had said so
        crc_call(invoker, server, body_of(MIB, 1))
        assert invoker.requests is not None and invoker.requests.shared == 1  # sent so once
        assert conn.takes_requests is False
        crc_call(invoker, server, body_of(MIB, 2))
        assert invoker.requests.shared == 1
    finally:
        server.kill()


class RawCaller:
    """A DEALER that announces itself as a caller of this host and sends request headers
    flagged shared with whatever descriptor it is given."""

    def __init__(self, endpoint: str) -> None:
        self.context: zmq.Context[Any] = zmq.Context()
        self.socket = self.context.socket(zmq.DEALER)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.ROUTING_ID, caller_marker() + os.urandom(8))
        self.socket.connect(endpoint)
        self.ids = iter(range(1, 1000))

    def call(self, descriptor: bytes) -> Reply:
        request = frames.Request(next(self.ids), b"Body", "crc", shared=True)
        self.socket.send_multipart([frames.encode_request(request), descriptor])
        header, body = self.socket.recv_multipart()
        head = frames.decode_reply(header)
        return Reply(head.status, body, head.repo_id)

    def close(self) -> None:
        self.socket.close()
        self.context.term()


def test_a_stale_or_bogus_descriptor_is_refused_never_run_on_torn_data(
    invoker: ZmqInvoker, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Lease 0: the slot of a request not yet read is written again at once. The server reads
    the first descriptor after that: MARSHAL (completed NO, the minor code that says
    unreadable), never the second body or a mix; so is a descriptor of no caller's memory.
    The server serves on."""
    monkeypatch.setenv("MIRO_SHM_CALL_SLOTS", "2")
    monkeypatch.setenv("MIRO_SHM_LEASE", "0")
    server = BodyProcess()
    raw = RawCaller(server.endpoint)
    pool = BodyPool(MIB, name="miro-requests")
    try:
        first = pool.put(body_of(MIB, 1))
        second = pool.put(body_of(MIB, 2))
        assert first is not None and second is not None
        assert shm.DESCRIPTOR.unpack(first)[3] == shm.DESCRIPTOR.unpack(second)[3]  # one slot
        bogus = shm.DESCRIPTOR.pack(os.getpid(), 9999, 1, 0, 2, 0, MIB)
        for descriptor in (first, bogus, b"short"):
            reply = raw.call(descriptor)
            with pytest.raises(MARSHAL) as refused:
                raise_system_exception(reply)
            assert refused.value.minor == UNREADABLE_MINOR
            assert refused.value.completed == CompletionStatus.NO
        assert pair_of(raw.call(second)) == (zlib.crc32(body_of(MIB, 2)), MIB)
        assert stats(invoker, server) == (1, 3)
    finally:
        pool.close()
        raw.close()
        server.kill()


CALLER = """
import struct, sys, zlib, zmq, random
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.transport.rpc.invoker import ZmqInvoker
invoker = ZmqInvoker(zmq.Context())
ref = ObjectRef("IDL:Test/Body:1.0", sys.argv[1], b"Body")
body = random.Random(5).randbytes(1 << 20)
while True:
    reply = invoker.invoke(ref, "slow_crc", body)
    ok = struct.unpack_from("<II", reply.body, 4) == (zlib.crc32(body), len(body))
    print(invoker.requests.shared if invoker.requests else 0, ok, flush=True)
"""


def test_kill_9_of_a_caller_mid_call_leaves_nothing_and_the_server_serves_on(
    invoker: ZmqInvoker,
) -> None:
    """Callers killed while the server runs their calls (slow_crc: 300 ms): nothing in
    /dev/shm, the server answers the next caller whole through its pool, and unmaps the dead
    callers' pools."""
    before = dev_shm()
    server = BodyProcess()
    try:
        for _ in range(2):
            caller = subprocess.Popen(
                [sys.executable, "-c", CALLER, server.endpoint],
                stdout=subprocess.PIPE,
                text=True,
                env=service_env(MIRO_SHM="1"),
            )
            assert caller.stdout is not None
            shared = 0
            while shared < 2:  # its first request goes in frames (before the first reply)
                words = caller.stdout.readline().split()
                assert len(words) == 2, "the caller stopped"
                shared = int(words[0])
                assert words[1] == "True"
            caller.send_signal(signal.SIGKILL)  # mid-call: it calls on and on
            caller.wait(10)
        stats(invoker, server)
        crc_call(invoker, server, body_of(MIB, 3))
        assert invoker.requests is not None and invoker.requests.shared == 1

        def only_ours_mapped() -> bool:
            crc_call(invoker, server, body_of(MIB, 4))
            return len(request_pools(server.pid)) == 1

        eventually(only_ours_mapped, 60)
    finally:
        server.kill()
    assert dev_shm() == before
