"""Large call replies through the server's shared memory (transport.rpc.shared): real server
processes (tests/procs/camera_server.py), callers in this process and in processes of their
own. Every image is checked against its CRC-32, so a body read while it was rewritten, or
shifted, is seen."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import zlib
from typing import Any

import Miro
import pytest
import zmq
from loopback import dev_shm, eventually, service_env
from procs.camera_server import Camera, pattern
from repo_paths import TESTS

from miro_gen.exceptions import COMM_FAILURE, TRANSIENT, CompletionStatus
from miro_gen.runtime.cdr import HEADER_LE, ObjectRef
from miro_gen.transport import shm, sockets
from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.invoker import ZmqInvoker
from miro_gen.transport.rpc.shared import SharedReplies, caller_marker

pytestmark = pytest.mark.skipif(not shm.available(), reason="shared memory needs Linux memfd")

OVERHEAD = len(Camera(0).image.serialize())  # bytes of a reply body beside the image's data
MIB = 1 << 20


class CameraProcess:
    """tests/procs/camera_server.py serving images of `size` bytes, in a process of its own."""

    def __init__(self, size: int, **env: str) -> None:
        self.size = size
        self.p = subprocess.Popen(
            [sys.executable, str(TESTS / "procs" / "camera_server.py"), str(size)],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(MIRO_SHM="1", **env),
        )
        assert self.p.stdout is not None
        line = self.p.stdout.readline().split()
        assert line and line[0] == "READY", f"server did not start: {line}"
        self.endpoint = line[1]

    def ref(self) -> ObjectRef:
        return ObjectRef("IDL:Miro/Camera:1.0", self.endpoint, b"Camera")

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGKILL)
        self.p.wait(10)


def crc(size: int) -> int:
    return zlib.crc32(pattern(size))


def mapped_pools(pid: int | str = "self") -> list[str]:
    """Mappings of servers' pools of replies in a process."""
    with open(f"/proc/{pid}/maps") as f:
        return [line for line in f if "miro-calls" in line]


@pytest.mark.parametrize("body", [shm.THRESHOLD - 1, shm.THRESHOLD, shm.THRESHOLD + 1, MIB])
def test_replies_from_the_threshold_on_come_through_shared_memory_whole(
    invoker: ZmqInvoker, body: int
) -> None:
    """Below the threshold in the frame; at and above it through the server's pool, also when
    the servant blocks and another thread forwards its reply (getWaitImage)."""
    before = dev_shm()
    server = CameraProcess(body - OVERHEAD)
    try:
        stub = Miro.Camera(server.ref(), invoker)
        for _ in range(3):
            image = stub.getImage()
            assert type(image.data) is bytes and zlib.crc32(image.data) == crc(server.size)
        for frame in (4, 5):
            image = stub.getWaitImage()  # handed over to another thread: forwarded
            assert image.frame == frame and zlib.crc32(image.data) == crc(server.size)
        assert invoker.shared.read == (5 if body >= shm.THRESHOLD else 0)
        assert bool(mapped_pools()) == (body >= shm.THRESHOLD)
    finally:
        server.kill()
    assert dev_shm() == before  # a memfd: never a file


def test_a_reply_over_the_callers_maximum_message_size_is_refused_as_in_a_frame() -> None:
    """The caller's limit holds for replies in shared memory too: a server with a larger one
    cannot hand it more than it would take in a frame."""
    server = CameraProcess(2 * MIB)
    context: zmq.Context[Any] = zmq.Context()
    sockets.configure(context, sockets.SocketPolicy(max_message_size=MIB))
    small = ZmqInvoker(context)
    try:
        with pytest.raises(COMM_FAILURE, match="more than the maximum message size"):
            Miro.Camera(server.ref(), small).getImage()
        assert small.shared.read == 0
    finally:
        small.close()
        context.term()
        server.kill()


def test_a_caller_that_does_not_announce_itself_gets_frames(
    invoker: ZmqInvoker, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A caller of another host, user or version (no marker in its routing id; here one with
    MIRO_SHM=0) gets its large replies in frames, as before."""
    server = CameraProcess(MIB)
    try:
        monkeypatch.setenv("MIRO_SHM", "0")
        plain = ZmqInvoker(zmq.Context())
        try:
            image = Miro.Camera(server.ref(), plain).getImage()
            assert zlib.crc32(image.data) == crc(MIB) and plain.shared.read == 0
        finally:
            plain.close()
            plain.context.term()
    finally:
        server.kill()


class GreedyCaller:
    """A raw DEALER that announces itself as a caller of this host and keeps the descriptors
    of its replies without reading them (as a caller that stalls, or dies, before it reads)."""

    def __init__(self, endpoint: str) -> None:
        self.context = zmq.Context()
        self.socket = self.context.socket(zmq.DEALER)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.ROUTING_ID, caller_marker() + os.urandom(8))
        self.socket.connect(endpoint)
        self.ids = iter(range(1, 1000))

    def get_image(self) -> tuple[bytes, bytes]:
        """(reply header, body) of a getImage request."""
        request = frames.Request(next(self.ids), b"Camera", "getImage")
        self.socket.send_multipart([frames.encode_request(request), HEADER_LE])
        header, body = self.socket.recv_multipart()
        return header, body

    def close(self) -> None:
        self.socket.close()
        self.context.term()


def test_an_exhausted_pool_falls_back_to_frames_and_returned_slots_are_reused(
    invoker: ZmqInvoker,
) -> None:
    server = CameraProcess(MIB, MIRO_SHM_CALL_SLOTS="2", MIRO_SHM_LEASE="3600")
    greedy = GreedyCaller(server.endpoint)
    try:
        held = [greedy.get_image() for _ in range(2)]
        assert all(frames.shared_reply_id(h) > 0 for h, _ in held)  # both slots taken
        stub = Miro.Camera(server.ref(), invoker)
        for _ in range(3):  # no free slot: in frames, never a wait
            assert zlib.crc32(stub.getImage().data) == crc(MIB)
        assert invoker.shared.read == 0
        reader = SharedReplies()
        try:
            whole = Camera(MIB).image.serialize()
            for _, descriptor in held:  # read late, still whole; the slots go back
                assert reader.body(descriptor, "getImage", False) == whole
            assert zlib.crc32(stub.getImage().data) == crc(MIB)
            assert invoker.shared.read == 1
        finally:
            reader.close()
    finally:
        greedy.close()
        server.kill()


def test_a_reply_read_after_its_lease_and_slot_were_taken_is_a_clean_error(
    invoker: ZmqInvoker,
) -> None:
    """Lease 0: a slot not yet read may be written again at once. The late reader of the first
    reply gets COMM_FAILURE (completed YES), never the second reply's bytes or a torn mix."""
    server = CameraProcess(MIB, MIRO_SHM_CALL_SLOTS="2", MIRO_SHM_LEASE="0")
    greedy = GreedyCaller(server.endpoint)
    reader = SharedReplies()
    try:
        (_, first), (_, second) = greedy.get_image(), greedy.get_image()
        assert first != second  # the same slot, written again
        with pytest.raises(COMM_FAILURE) as failure:
            reader.body(first, "getImage", False)
        assert failure.value.completed == CompletionStatus.YES
        body = reader.body(second, "getImage", False)
        assert body == Camera(MIB).image.serialize()
    finally:
        reader.close()
        greedy.close()
        server.kill()


def test_a_reply_read_in_place_is_never_rewritten_while_its_thread_holds_it() -> None:
    """Lease 0, two slots: the slot of a reply read in place (as a stub reads it) stays as it
    was while later replies come, until the thread's next call gives it back."""
    server = CameraProcess(MIB, MIRO_SHM_CALL_SLOTS="2", MIRO_SHM_LEASE="0")
    greedy = GreedyCaller(server.endpoint)
    reader = SharedReplies()
    whole = Camera(MIB).image.serialize()
    try:
        first = shm.Descriptor(*shm.DESCRIPTOR.unpack(greedy.get_image()[1]))
        view = reader.body(shm.DESCRIPTOR.pack(*first), "getImage", True)
        assert isinstance(view, memoryview) and view.readonly and view == whole
        later = [shm.Descriptor(*shm.DESCRIPTOR.unpack(greedy.get_image()[1])) for _ in range(3)]
        assert {d.slot for d in later} == {1 - first.slot}  # never the held one
        assert view == whole
        reader.give_back()  # the thread's next call
        after = shm.Descriptor(*shm.DESCRIPTOR.unpack(greedy.get_image()[1]))
        assert after.slot == first.slot  # lowest first, free again
    finally:
        reader.close()
        greedy.close()
        server.kill()


def test_kill_9_of_the_server_mid_call_leaves_nothing_mapped_and_a_new_one_serves(
    invoker: ZmqInvoker,
) -> None:
    before = dev_shm()
    server = CameraProcess(MIB)
    stub = Miro.Camera(server.ref(), invoker)
    outcome: list[str] = []

    def calls() -> None:
        for _ in range(10_000):
            try:
                image = stub.getWaitImage()
            except (COMM_FAILURE, TRANSIENT) as e:
                outcome.append(type(e).__name__)
                return
            if zlib.crc32(image.data) != crc(MIB):
                outcome.append("torn")
                return
        outcome.append("never failed")

    thread = threading.Thread(target=calls)
    thread.start()
    eventually(lambda: invoker.shared.read >= 3, 60)
    assert mapped_pools()
    server.kill()
    thread.join(60)
    assert outcome in (["COMM_FAILURE"], ["TRANSIENT"])
    assert mapped_pools() == []  # its pool unmapped once its server is gone
    assert dev_shm() == before
    again = CameraProcess(MIB)
    try:
        image = Miro.Camera(again.ref(), invoker).getImage()
        assert zlib.crc32(image.data) == crc(MIB)
    finally:
        again.kill()


CALLER = """
import sys, zlib, zmq
import Miro
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.transport.rpc.invoker import ZmqInvoker
invoker = ZmqInvoker(zmq.Context())
stub = Miro.Camera(ObjectRef("IDL:Miro/Camera:1.0", sys.argv[1], b"Camera"), invoker)
while True:
    image = stub.getImage()
    print(invoker.shared.read, zlib.crc32(image.data), flush=True)
"""


def test_kill_9_of_callers_mid_call_never_holds_up_the_server(invoker: ZmqInvoker) -> None:
    """Two slots, three caller processes killed while they call: the server serves the next
    caller whole, through shared memory once their slots are back (read, or freed with the
    lease), in frames meanwhile."""
    before = dev_shm()
    server = CameraProcess(MIB, MIRO_SHM_CALL_SLOTS="2", MIRO_SHM_LEASE="2")
    try:
        for _ in range(3):
            caller = subprocess.Popen(
                [sys.executable, "-c", CALLER, server.endpoint],
                stdout=subprocess.PIPE,
                text=True,
                env=service_env(MIRO_SHM="1"),
            )
            assert caller.stdout is not None
            read = 0
            while read < 3:  # in frames while its predecessors' slots wait for their lease
                words = caller.stdout.readline().split()
                assert len(words) == 2, "the caller stopped"
                read, checksum = int(words[0]), int(words[1])
                assert checksum == crc(MIB)
            caller.send_signal(signal.SIGKILL)  # mid-call: it calls on and on
            caller.wait(10)
        stub = Miro.Camera(server.ref(), invoker)
        assert zlib.crc32(stub.getImage().data) == crc(MIB)

        def shared_again() -> bool:
            assert zlib.crc32(stub.getImage().data) == crc(MIB)
            return invoker.shared.read > 0

        eventually(shared_again, 60)
    finally:
        server.kill()
    assert dev_shm() == before
