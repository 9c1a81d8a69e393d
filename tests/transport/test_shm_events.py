"""Large events through shared memory between processes of one host (transport.shm):
real supplier and consumer processes on a channel hosted by `miro naming --channel`. Every
image carries the CRC-32 of its data, so a payload read while it was rewritten is seen."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator

import Miro
import pytest
from loopback import NamingProcess, Recorder, dev_shm, eventually, service_env
from miro_cli import REPO

from miro_gen import EventChannelFactory, Server, StructuredPushSupplier
from miro_gen.transport import shm
from miro_gen.transport.events import StructuredEvent, credits

pytestmark = pytest.mark.skipif(not shm.available(), reason="shared memory needs Linux memfd")

PROCS = str(REPO / "tests" / "shm_procs.py")
MIB = 1 << 20


@pytest.fixture(scope="module")
def channel_naming() -> Iterator[str]:
    process = NamingProcess(options=("--channel", "Cams"))
    yield process.endpoint
    process.stop()


class Proc:
    """A process of tests/shm_procs.py, its output lines collected by a thread."""

    def __init__(self, *args: str, **env: str) -> None:
        self.p = subprocess.Popen(
            [sys.executable, PROCS, *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(**{"MIRO_SHM": "1", **env}),
        )
        self.lines: list[str] = []
        self._events: list[tuple[int, bool]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            words = line.split()
            if len(words) == 3 and words[0] == "E":
                self._events.append((int(words[1]), words[2] == "1"))
            else:  # (any other line is kept, not the end of this thread: a test shows it)
                self.lines.append(line.strip())

    def has(self, prefix: str) -> bool:
        return any(line.startswith(prefix) for line in self.lines)

    def line(self, prefix: str) -> list[str]:
        return [line for line in self.lines if line.startswith(prefix)][-1].split()

    def events(self) -> list[tuple[int, bool]]:
        return list(self._events)

    def stats(self) -> list[int]:
        """received, missed, dropped, torn, segments mapped."""
        before = len([x for x in self.lines if x.startswith("STATS")])
        self.send("STATS")
        eventually(lambda: len([x for x in self.lines if x.startswith("STATS")]) > before, 30)
        return [int(w) for w in self.line("STATS")[1:]]

    def send(self, line: str) -> None:
        assert self.p.stdin is not None
        self.p.stdin.write(line + "\n")
        self.p.stdin.flush()

    def stop(self, sig: int | None = None) -> None:
        if self.p.poll() is None:
            if sig is None:
                assert self.p.stdin is not None
                self.p.stdin.close()
            else:
                self.p.send_signal(sig)
        try:
            self.p.wait(15)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()


@pytest.fixture
def procs() -> Iterator[Callable[..., Proc]]:
    started: list[Proc] = []

    def start(*args: str, **env: str) -> Proc:
        p = Proc(*args, **env)
        started.append(p)
        return p

    yield start
    for p in started:
        p.stop(signal.SIGKILL)


def consumer(procs: Callable[..., Proc], naming: str, *args: str) -> Proc:
    c = procs("consume", naming, "Cams", *args)
    eventually(lambda: c.has("READY"), 30)
    return c


def segments_of(pid: int) -> list[str]:
    """The ring segments process `pid` has open or mapped."""
    found = []
    try:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if "miro-events" in target:
                found.append(target)
        with open(f"/proc/{pid}/maps") as f:
            found += [line for line in f if "miro-events" in line]
    except OSError:
        return []
    return found


def knows_keep_all_consumers(supplier: StructuredPushSupplier, type_name: str, n: int) -> bool:
    """Whether the supplier has every subscription of `n` keep-all consumers of this host
    (each sends its credit subscription last): before, the first events may go in full, or
    to one of them only (the subscriptions reach it in more than one read)."""
    supplier.has_subscribers(type_name)  # (takes the subscriptions as they are now)
    t = supplier._topics[type_name]
    readers = t.credits.readers if t.credits is not None else []
    return t.shared and t.keep_all == n and len(readers) == n


def test_megabyte_images_reach_consumer_processes_through_shared_memory_whole(
    channel_naming: str, procs: Callable[..., Proc]
) -> None:
    before = dev_shm()
    keep_all = consumer(procs, channel_naming, "0", "0")
    keep_last = consumer(procs, channel_naming, "10", "0")
    supplier = procs("supply", channel_naming, "Cams", "300", str(MIB))
    eventually(lambda: supplier.has("SENT"), 60)
    assert supplier.line("RING") == ["RING", "yes"]
    assert supplier.line("SENT") == ["SENT", "300", "0"]
    eventually(lambda: len(keep_all.events()) == 300, 60)
    assert keep_all.events() == [(n, True) for n in range(300)]  # all, in order, untorn
    received, missed, dropped, torn, mapped = keep_all.stats()
    assert (received, missed, dropped, torn, mapped) == (300, 0, 0, 0, 1)
    got = keep_last.events()
    assert all(ok for _, ok in got) and [n for n, _ in got] == sorted({n for n, _ in got})
    assert dev_shm() == before  # a memfd: never a file


def test_a_supplier_started_after_a_consumer_that_needs_frames_sends_it_every_image(
    channel_naming: str, procs: Callable[..., Proc]
) -> None:
    """A consumer that maps rings and one that does not (shared memory off here; or another
    host) subscribe to the same prefix, then the camera starts. The channel's proxy passes each
    prefix on once to a supplier that connects after its subscribers, so by counting them the
    supplier took the two for one consumer of this host: every image went through shared
    memory and the other consumer got none (0 of 20). Both get all 20, whole."""
    mapped = consumer(procs, channel_naming, "0", "0")
    framed = procs("consume", channel_naming, "Cams", "0", "0", MIRO_SHM="0")
    eventually(lambda: framed.has("READY"), 30)
    supplier = procs("supply", channel_naming, "Cams", "20", str(MIB), "0.01")
    eventually(lambda: supplier.has("SENT"), 60)
    assert supplier.line("SENT")[1:] == ["20", "0"]
    for c in (mapped, framed):
        eventually(lambda c=c: len(c.events()) >= 20, 60)  # type: ignore[misc]
        assert c.events() == [(n, True) for n in range(20)]
    assert framed.stats()[4] == 0  # it read no shared memory


def test_a_consumer_lapped_by_its_supplier_never_sees_a_torn_payload(
    channel_naming: str, procs: Callable[..., Proc]
) -> None:
    """A ring of two slots, a handler far slower than the supplier: most descriptors are stale
    when read, or the slot is rewritten during the read; each such event is dropped and
    counted, and every event delivered is whole."""
    slow = consumer(procs, channel_naming, "10", "0.01")
    supplier = procs("supply", channel_naming, "Cams", "400", str(MIB), MIRO_SHM_SLOTS="2")
    eventually(lambda: supplier.has("SENT"), 60)
    assert supplier.line("SENT")[1:] == ["400", "0"]  # keep-last: the supplier never waits

    def settled() -> bool:  # every event delivered, or counted as lost or dropped
        received, missed, dropped, _, _ = slow.stats()
        return received + dropped + missed >= 400

    eventually(settled, 60)
    received, missed, dropped, _, _ = slow.stats()
    got = slow.events()
    assert len(got) == received and received > 0
    assert all(ok for _, ok in got), [n for n, ok in got if not ok]
    assert dropped > 0  # it was lapped
    assert received + dropped + missed >= 400


def test_kill_9_of_a_supplier_leaves_no_segment_and_a_new_one_is_received(
    channel_naming: str, procs: Callable[..., Proc]
) -> None:
    before = dev_shm()
    c = consumer(procs, channel_naming, "0", "0")
    first = procs("supply", channel_naming, "Cams", "0", str(MIB), "0.005")
    eventually(lambda: len(c.events()) > 50, 60)
    first.stop(signal.SIGKILL)
    # The consumer unmaps the dead supplier's segment (it looks every second).
    eventually(lambda: not segments_of(c.p.pid), 30, lambda: str(segments_of(c.p.pid)))
    assert c.stats()[4] == 0
    assert dev_shm() == before
    n = len(c.events())
    second = procs("supply", channel_naming, "Cams", "100", str(MIB))
    eventually(lambda: second.has("SENT"), 60)
    eventually(lambda: len(c.events()) >= n + 100, 60)
    assert all(ok for _, ok in c.events())
    assert c.events()[-100:] == [(k, True) for k in range(100)]


def test_kill_9_of_a_keep_all_consumer_holds_up_neither_supplier_nor_others(
    channel_naming: str, procs: Callable[..., Proc]
) -> None:
    """A keep-all consumer killed with slots unread: its lane is freed (the kernel drops its
    lock), so the supplier does not wait for its credits and the other consumer gets all."""
    doomed = consumer(procs, channel_naming, "0", "0.05")
    other = consumer(procs, channel_naming, "0", "0")
    supplier = procs("supply", channel_naming, "Cams", "0", str(MIB), "0.005")
    eventually(lambda: len(doomed.events()) > 5, 60)
    doomed.stop(signal.SIGKILL)
    n = len(other.events())
    eventually(lambda: len(other.events()) > n + 300, 60)
    supplier.send("x")  # nothing: it is still pushing
    got = other.events()
    assert all(ok for _, ok in got)
    assert [k for k, _ in got] == list(range(got[0][0], got[0][0] + len(got)))  # no gap
    assert other.stats()[1:4] == [0, 0, 0]
    supplier.stop(signal.SIGKILL)
    eventually(lambda: not segments_of(other.p.pid), 30)


def test_a_zero_copy_consumer_gets_read_only_views_that_numpy_cannot_write(
    servers: Callable[[str], Server], monkeypatch: pytest.MonkeyPatch
) -> None:
    """In one process too (its own lane, through /proc/self/fd): with zero_copy the image data
    is a read-only memoryview of the slot while the handler runs; without, bytes."""
    np = pytest.importorskip("numpy")
    monkeypatch.setenv("MIRO_SHM", "1")
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Views")
    supplier = StructuredPushSupplier(channel)
    seen: list[tuple[str, bool, str]] = []

    class Viewer(Recorder):
        def push_structured_event(self, event: StructuredEvent) -> None:
            data = event.payload.data
            array = np.frombuffer(data, dtype=np.uint8)
            try:
                array[0] = 1
                wrote = "wrote"
            except ValueError:
                wrote = "refused"
            seen.append((type(data).__name__, bool(array.flags.writeable), wrote))
            super().push_structured_event(event)

    viewer = Viewer(channel)
    viewer.zero_copy = True
    plain = Recorder(channel)
    for c in (viewer, plain):
        c.set_subscriptions([("r", "Image")])
    eventually(lambda: knows_keep_all_consumers(supplier, "Image", 2), 60)
    data = bytes(range(256)) * 4096
    form = Miro.ImageFormatIDL(512, 256, Miro.IMAGE_RGB8, 1536)
    for n in range(3):
        supplier.push("Image", Miro.ImageEventIDL(Miro.TimeIDL(n, 0), n, form, data))
    eventually(lambda: len(viewer.events) == 3 and len(plain.events) == 3, 60)
    assert supplier._topics["Image"].ring is not None
    assert seen == [("memoryview", False, "refused")] * 3
    assert all(type(e.payload.data) is bytes and e.payload.data == data for e in plain.events)


def test_a_keep_all_consumer_killed_with_slots_unread_costs_no_event_before_it_unsubscribes(
    servers: Callable[[str], Server], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Its lane freed (its lock gone with it), a ring of two slots goes on at once: it does not
    wait, and drop an event for every consumer, until the dead consumer's subscriptions leave
    the channel, which a loaded host takes its time over (the subscriptions, credit tables and
    lanes are made here by hand, so that they stay as long as the test says)."""
    monkeypatch.setenv("MIRO_SHM", "1")
    monkeypatch.setenv("MIRO_SHM_SLOTS", "2")
    supplier = StructuredPushSupplier(EventChannelFactory(servers("r")).create_channel("Lanes"))
    eventually(lambda: supplier._connected, 30)
    prefix = supplier._topic("Image").frame
    tables = [credits.CreditTable() for _ in range(2)]
    marked = [shm.topic_marker() + prefix, shm.keep_all_marker() + prefix]
    changes = [
        (True, sub)
        for t in tables
        for sub in (prefix, *marked, t.subscription(credits.credit_marker(), prefix))
    ]
    done = threading.Event()

    def subscribe() -> None:
        supplier._subscriptions_changed(changes)
        done.set()

    supplier.reactor.call_soon(subscribe)
    assert done.wait(30) and supplier.has_subscribers("Image")
    data = bytes(256) * 4096
    form = Miro.ImageFormatIDL(512, 256, Miro.IMAGE_RGB8, 1536)

    def push(n: int) -> None:
        supplier.push("Image", Miro.ImageEventIDL(Miro.TimeIDL(n, 0), n, form, data))

    push(0)
    ring = supplier._topics["Image"].ring
    assert ring is not None and ring.slots == 2
    lanes = [shm.Segment(os.getpid(), ring.fd, ring.segment_id, True, 0) for _ in tables]
    survivor, doomed = lanes
    survivor.ack(1)
    doomed.ack(1)  # it read write 0, then dies with write 1 unread
    push(1)
    survivor.ack(2)
    doomed.close()
    tables[1].close()  # kill -9: its lane's lock and its table go with the process
    for n in range(2, 6):
        push(n)
        survivor.ack(n + 1)
    assert supplier.dropped == 0 and ring.stalls == 0  # and no put waited the dead lane out
    survivor.close()
    tables[0].close()


def test_a_keep_all_consumer_of_a_topic_through_two_subscriptions_holds_one_lane(
    servers: Callable[[str], Server], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Subscribed to r/Image and to r/*, it says twice that it keeps all, and maps the ring
    once: the ring waits for one lane, not for a second that never comes (every event after the
    first lap waited the bound and was dropped)."""
    monkeypatch.setenv("MIRO_SHM", "1")
    monkeypatch.setenv("MIRO_SHM_SLOTS", "2")
    channel = EventChannelFactory(servers("r")).create_channel("Twice")
    supplier = StructuredPushSupplier(channel)
    everything = Recorder(channel)
    everything.set_subscriptions([("r", "Image"), ("r", "*")])

    def subscribed() -> bool:
        supplier.has_subscribers("Image")
        t = supplier._topics["Image"]
        return t.shared and t.keep_all == 2 and t.credits is not None and bool(t.credits.readers)

    eventually(subscribed, 60)
    data = bytes(256) * 4096
    form = Miro.ImageFormatIDL(512, 256, Miro.IMAGE_RGB8, 1536)
    for n in range(8):
        supplier.push("Image", Miro.ImageEventIDL(Miro.TimeIDL(n, 0), n, form, data))
    eventually(lambda: len(everything.events) + supplier.dropped >= 8, 60)
    assert supplier.dropped == 0
    assert [e.payload.frame for e in everything.events] == list(range(8))
    ring = supplier._topics["Image"].ring
    assert ring is not None and ring.stalls == 0  # no put waited out a second lane
