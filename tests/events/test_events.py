"""Event channels over real sockets on loopback: subscriptions, offers, batches, slow consumers."""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable

import Miro
import pytest
import zmq
from loopback import Recorder, RunningServer, eventually

from miro_gen import (
    KEEP_ALL,
    EventChannelFactory,
    Server,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)


def event(n: int) -> Miro.ExampleEventIDL:
    return Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), -float(n)))


def test_subscriptions_select_by_domain_and_type(servers: Callable[[str], Server]) -> None:
    host = servers("robot1")
    channel = EventChannelFactory(host).create_channel("Events")
    assert EventChannelFactory(host).create_channel("Events").name == "robot1/Events"
    robot1 = StructuredPushSupplier(channel)
    robot2 = StructuredPushSupplier(channel, domain_name="robot2")
    listener = servers("gui")
    remote = listener.resolve_channel("robot1/Events")
    everything, exact, by_type, by_domain = (Recorder(remote) for _ in range(4))
    everything.set_subscriptions([("*", "*")])
    exact.set_subscriptions([("robot2", "ExampleEvent")])
    by_type.set_subscriptions([("*", "ExampleEvent")])
    by_domain.set_subscriptions([("robot1", "*")])
    eventually(lambda: robot1.has_subscribers("Other") and robot2.has_subscribers("ExampleEvent"))
    eventually(lambda: robot2.has_subscribers("Other"))  # (*, *) matches every topic
    n = 0
    while len(everything.events) < 4 * 3 and n < 50:  # first events may beat the connections
        for s, t in ((robot1, "ExampleEvent"), (robot2, "ExampleEvent"), (robot1, "Other")):
            s.push(t, event(n))
        n += 1
        time.sleep(0.02)
    time.sleep(0.2)

    def seen(r: Recorder) -> set[tuple[str, str]]:
        return {(e.domain_name, e.type_name) for e in r.events}

    assert seen(everything) == {
        ("robot1", "ExampleEvent"),
        ("robot2", "ExampleEvent"),
        ("robot1", "Other"),
    }
    assert seen(exact) == {("robot2", "ExampleEvent")}
    assert seen(by_type) == {("robot1", "ExampleEvent"), ("robot2", "ExampleEvent")}
    assert seen(by_domain) == {("robot1", "ExampleEvent"), ("robot1", "Other")}
    e = exact.events[-1]
    assert isinstance(e.payload, Miro.ExampleEventIDL)
    assert e.payload == event(e.payload.counter)
    assert e.stamp <= e.publish_time <= time.time()
    assert e.type_hash == Miro.ExampleEventIDL._type_hash


def test_nobody_subscribed_means_nothing_encoded(servers: Callable[[str], Server]) -> None:
    host = servers("r")
    supplier = StructuredPushSupplier(EventChannelFactory(host).create_channel())
    time.sleep(0.2)
    assert not supplier.has_subscribers("ExampleEvent")

    class Exploding:
        _type_hash = Miro.ExampleEventIDL._type_hash

        def serialize(self) -> bytes:
            raise AssertionError("encoded although nobody listens")

    assert supplier.push("ExampleEvent", Exploding()) is False
    consumer = Recorder(servers("c").resolve_channel("r/EventChannel"))
    consumer.set_subscriptions([("r", "ExampleEvent")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    consumer.set_subscriptions([])
    eventually(lambda: not supplier.has_subscribers("ExampleEvent"))


def test_sequence_numbers_count_what_a_late_consumer_missed(
    servers: Callable[[str], Server],
) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Seq")
    supplier = StructuredPushSupplier(channel)
    consumer = Recorder(servers("c").resolve_channel("r/Seq"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    for n in range(200):
        supplier.push("ExampleEvent", event(n))
    eventually(lambda: len(consumer.events) == 200)
    seqs = [e.seq for e in consumer.events]
    assert seqs == list(range(seqs[0], seqs[0] + 200))
    assert consumer.missed == 0


def test_a_slow_consumer_does_not_slow_the_supplier(servers: Callable[[str], Server]) -> None:
    """The supplier pushes a whole flood while one consumer is stuck on its first event."""
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Slow")
    supplier = StructuredPushSupplier(channel)
    gate = threading.Event()
    fast = Recorder(servers("fast").resolve_channel("r/Slow"))
    slow = Recorder(servers("slow").resolve_channel("r/Slow"), gate=gate)
    for c in (fast, slow):
        c.set_subscriptions([("*", "*")])
    eventually(lambda: sum(supplier._subscriptions.values()) >= 2)  # both
    time.sleep(0.3)
    total = 30_000
    try:
        for n in range(total):
            supplier.push("ExampleEvent", event(n))
        eventually(lambda: len(fast.events) >= total * 0.99, 30)
        eventually(slow.holding.is_set, 30)
        assert slow.events == []  # all pushed while it was stuck on its first
    finally:
        gate.set()
    # Released, the slow one delivers what it kept, in order, and counts what it missed: what
    # it got and missed add up to the span of sequence numbers it saw (once it has caught up
    # with its own count: both change while it delivers).

    def accounted() -> bool:
        got = list(slow.events)
        span = got[-1].seq - got[0].seq + 1 if got else 0
        return bool(got) and slow.missed == span - len(got) and len(got) == len(slow.events)

    eventually(accounted, 30)
    seqs = [e.seq for e in slow.events]
    assert seqs == sorted(set(seqs))


def test_undecodable_events_are_reported_not_delivered(
    servers: Callable[[str], Server], capfd: pytest.CaptureFixture[str]
) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Hash")
    supplier = StructuredPushSupplier(channel)
    consumer = Recorder(servers("c").resolve_channel("r/Hash"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))

    class Impostor:  # same name, another layout: its hash is unknown to everybody
        _type_hash = "ab" * 32

        def serialize(self) -> bytes:
            return b"\x00\x01\x00\x00" + bytes(8)

    for _ in range(3):
        supplier.push("ExampleEvent", Impostor())
    supplier.push("ExampleEvent", event(1))
    eventually(lambda: len(consumer.events) == 1)
    # Counted once the search for generated packages (in a thread of its own) is over.
    eventually(lambda: consumer.undecodable == 3)
    assert consumer.events[0].payload == event(1)


def test_malformed_event_frames_are_dropped(servers: Callable[[str], Server]) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Bad")
    consumer = Recorder(servers("c").resolve_channel("r/Bad"))
    consumer.set_subscriptions([("*", "*")])
    rogue = zmq.Context.instance().socket(zmq.PUB)
    rogue.setsockopt(zmq.LINGER, 0)
    rogue.connect(channel.supplier_endpoint)
    time.sleep(0.3)
    bad = [[b"x"], [b"r\0T\0", b"short"], [b"r\0T\0", b"\x09" + bytes(50)], [b"no-nul", b""]]
    for parts in bad:
        rogue.send_multipart(parts)
    supplier = StructuredPushSupplier(channel)
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    supplier.push("ExampleEvent", event(5))
    eventually(lambda: len(consumer.events) == 1)
    assert consumer.events[0].payload == event(5)
    rogue.close()


def test_events_of_other_types_are_not_counted_as_missed(
    servers: Callable[[str], Server],
) -> None:
    """Sequence numbers count per type: a consumer of one type sees no gaps from the others."""
    host = servers("r")
    supplier = StructuredPushSupplier(EventChannelFactory(host).create_channel("Two"))
    remote = servers("c").resolve_channel("r/Two")
    only_a, only_b = Recorder(remote), Recorder(remote)
    only_a.set_subscriptions([("r", "A")])
    only_b.set_subscriptions([("r", "B")])
    eventually(lambda: supplier.has_subscribers("A") and supplier.has_subscribers("B"))
    for n in range(100):
        supplier.push("A", event(n))
        supplier.push("B", event(n))
        time.sleep(0.001)  # several batches, so the gaps would show between them
    eventually(lambda: len(only_a.events) == 100 and len(only_b.events) == 100)
    assert [e.payload.counter for e in only_a.events] == list(range(100))
    assert only_a.missed == only_b.missed == 0


def test_a_turn_with_more_events_than_a_batch_holds(servers: Callable[[str], Server]) -> None:
    """Events pushed within one reactor turn beyond a frame's 65,535 are split, not lost."""
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Many")
    supplier = StructuredPushSupplier(channel)
    consumer = Recorder(servers("c").resolve_channel("r/Many"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    total = 70_000
    value = event(1)
    # All pushed on the reactor thread, in one turn: they leave in frames as they fill.
    channel.reactor.call_soon(lambda: [supplier.push("ExampleEvent", value) for _ in range(total)])
    eventually(lambda: len(consumer.events) == total, 30)
    assert consumer.missed == 0


def test_a_blocked_reactor_does_not_make_the_supplier_queue_grow(
    servers: Callable[[str], Server],
) -> None:
    """While the reactor cannot send, push() queues a bounded number of events and counts
    those it drops; consumers see the drop as a gap."""
    from miro_gen.transport.events import QUEUE_EVENTS

    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Blocked")
    supplier = StructuredPushSupplier(channel)
    consumer = Recorder(servers("c").resolve_channel("r/Blocked"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    supplier.push("ExampleEvent", event(0))
    eventually(lambda: len(consumer.events) == 1)
    unblock = threading.Event()
    channel.reactor.call_soon(unblock.wait, 30)
    extra = 5_000
    for n in range(QUEUE_EVENTS + extra):
        supplier.push("ExampleEvent", event(n))
    assert supplier.dropped == extra
    unblock.set()
    eventually(lambda: len(consumer.events) == 1 + QUEUE_EVENTS, 30)
    supplier.push("ExampleEvent", event(0))
    eventually(lambda: len(consumer.events) == 2 + QUEUE_EVENTS)
    assert consumer.missed == extra


def test_events_larger_than_a_frame_travel_alone(servers: Callable[[str], Server]) -> None:
    """An event above the frame's byte limit still leaves, in a frame of its own."""
    from miro_gen.transport.events import MAX_BATCH_BYTES

    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Big")
    supplier = StructuredPushSupplier(channel)
    consumer = Recorder(servers("c").resolve_channel("r/Big"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("Group"))
    points = [Miro.ExampleStructIDL(float(i), -float(i)) for i in range(MAX_BATCH_BYTES // 16 + 1)]
    groups = [Miro.ExampleGroupIDL(n, points) for n in range(3)]
    channel.reactor.call_soon(lambda: [supplier.push("Group", g) for g in groups])
    eventually(lambda: len(consumer.events) == 3)
    assert [e.payload for e in consumer.events] == groups
    assert consumer.missed == 0


def test_events_refused_at_the_high_water_mark_are_counted(
    servers: Callable[[str], Server], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A channel that stops reading: the supplier's frames pile up to its high-water mark and
    the kernel's buffers, then push() goes on without blocking and counts what it dropped."""
    from miro_gen.transport import events
    from miro_gen.transport.events import supplier as event_supplier

    monkeypatch.setattr(event_supplier, "HWM", 10)
    host = servers("r")
    stuck = zmq.Context.instance().socket(zmq.XSUB)  # a channel whose proxy never reads
    stuck.setsockopt(zmq.LINGER, 0)
    stuck.setsockopt(zmq.RCVHWM, 10)
    port = stuck.bind_to_random_port("tcp://127.0.0.1")
    channel = events.EventChannel("r/Stuck", f"tcp://127.0.0.1:{port}", "", host.reactor(), "r")
    supplier = StructuredPushSupplier(channel)
    stuck.send(b"\x01")  # subscribe to everything (sent to the supplier once it attaches,
    # which the socket notices when used: EVENTS processes its commands without reading)
    eventually(lambda: stuck.getsockopt(zmq.EVENTS) >= 0 and supplier.has_subscribers("Group"))
    points = [Miro.ExampleStructIDL(float(i), 0.0) for i in range(events.MAX_BATCH_BYTES // 16)]
    group = Miro.ExampleGroupIDL(0, points)  # a frame of its own
    total = 400  # ~100 MB: beyond what loopback buffers hold
    channel.reactor.call_soon(lambda: [supplier.push("Group", group) for _ in range(total)])
    eventually(lambda: supplier.sent + supplier.dropped == total, 30)  # no push() blocked
    assert supplier.dropped > 0
    supplier.close()
    stuck.close()


def test_a_slow_consumer_with_a_backlog_stops_promptly(
    naming: str, servers: Callable[[str], Server]
) -> None:
    """shutdown() takes effect after the event being delivered, not after the whole backlog:
    asked to stop while its consumer is held in the first of 2,000 events, the Server delivers
    none of the others."""
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Backlog")
    supplier = StructuredPushSupplier(channel)
    slow_server = RunningServer(naming, "slow")
    gate = threading.Event()
    slow = Recorder(slow_server.server.resolve_channel("r/Backlog"), gate=gate)
    slow.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    value = event(1)
    channel.reactor.call_soon(lambda: [supplier.push("ExampleEvent", value) for _ in range(2000)])
    eventually(lambda: slow.holding.is_set() and supplier.sent == 2000, 30)
    time.sleep(0.5)  # let the backlog reach the slow Server
    slow_server.server.shutdown()  # returns at once; the reactor is held in the first event
    gate.set()
    slow_server.thread.join(30)
    assert not slow_server.thread.is_alive()
    assert len(slow.events) == 1


def test_a_type_is_found_by_hash_without_its_package_imported() -> None:
    """A recorder or echo tool handles any event type: it finds generated packages itself."""
    import subprocess
    import sys

    from loopback import service_env

    code = (
        "import sys\n"
        "from miro_gen.runtime.cdr import type_for_hash\n"
        f"cls = type_for_hash({Miro.GpsDataIDL._type_hash!r})\n"
        "print(cls.__module__, cls.__name__)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=service_env()
    )
    assert done.stdout.strip() == "Miro.Gps_idl GpsDataIDL", done.stderr


def test_a_consumer_finds_a_type_its_program_never_imported(
    naming: str, servers: Callable[[str], Server]
) -> None:
    """A consumer whose program never imported the payload's package: the generated packages
    on the path are imported in a thread of their own (runtime.registry), and the frames that
    came meanwhile wait for it, so every event is delivered, decoded, in order."""
    import subprocess
    import sys

    from loopback import service_env

    host = servers("r")
    supplier = StructuredPushSupplier(EventChannelFactory(host).create_channel("Unknown"))
    code = (
        "import sys, threading\n"
        "from miro_gen import Server, StructuredPushConsumer\n"
        "from miro_gen.runtime import registry\n"
        "search = registry.discover\n"
        "def spy():\n"
        "    print('search in', threading.current_thread().name, flush=True)\n"
        "    return search()\n"
        "registry.discover = spy\n"
        f"server = Server(['c', '--naming', {naming!r}, '-MNC', 'c'])\n"
        "class C(StructuredPushConsumer):\n"
        "    def push_structured_event(self, event):\n"
        "        p = event.payload\n"
        "        print(type(p).__name__, p.counter, event.seq, flush=True)\n"
        "        if event.seq == 2:\n"
        "            server.shutdown()\n"
        "C(server.resolve_channel('r/Unknown')).set_subscriptions([('*', '*')])\n"
        "print('READY', 'Miro' in sys.modules, flush=True)\n"
        "server.run()\n"
    )
    consumer = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=service_env()
    )
    try:
        assert consumer.stdout is not None
        assert consumer.stdout.readline().split() == ["READY", "False"]
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))
        values = [event(n) for n in range(3)]
        host.reactor().call_soon(lambda: [supplier.push("ExampleEvent", v) for v in values])
        out, _ = consumer.communicate(timeout=60)
    finally:
        consumer.kill()
    lines = out.splitlines()
    assert lines == ["search in miro-type-discovery"] + [
        f"ExampleEventIDL {n} {n}" for n in range(3)
    ]


def test_a_delivered_event_is_not_kept_while_the_rest_of_its_turn_is_delivered(
    servers: Callable[[str], Server],
) -> None:
    """A consumer delivering a backlog keeps no reference to the events already delivered:
    with camera images, a turn that held them all until its end kept a decoded megabyte alive
    per event (and freed them all at once, to be faulted in again: issue 29's regression)."""
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Backlog")
    supplier = StructuredPushSupplier(channel)
    gate = threading.Event()
    holding = threading.Event()
    previous: list[StructuredEvent] = []  # the last event delivered, held only here
    others: list[int] = []  # per delivery: how many others held the one before

    class Checking(StructuredPushConsumer):
        def push_structured_event(self, event: StructuredEvent) -> None:
            if not gate.is_set():  # the first waits: the rest queue up behind it
                holding.set()
                gate.wait(60)
            if previous:
                held = [r for r in gc.get_referrers(previous[0]) if r is not previous]
                others.append(len(held))
            previous[:] = [event]

    consumer = Checking(servers("c").resolve_channel("r/Backlog"), depth=KEEP_ALL)
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    total = 200
    try:
        supplier.push("ExampleEvent", event(0))
        eventually(holding.is_set, 30)
        for n in range(1, total):
            supplier.push("ExampleEvent", event(n))
    finally:
        gate.set()
    eventually(lambda: len(others) == total - 1, 30)
    assert consumer.missed == 0
    assert others == [0] * (total - 1)
