"""Event channels under load and attack (issue 21), between real processes: channels that come
back after their host restarts, keep-last and latest-only consumers that show their lag and
drops, sequence numbers that cannot be spoofed into nonsense, bounded per-supplier state,
byte-bounded queues, events larger than a message, and CURVE keeping strangers out."""

from __future__ import annotations

import queue
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
import zmq
from loopback import (
    NamingProcess,
    Recorder,
    RunningServer,
    eventually,
    rss_mb,
    run_miro,
    service_env,
)
from repo_paths import TESTS

from miro_gen import TRANSIENT, Client, EventChannelFactory, StructuredPushSupplier
from miro_gen.log import PEER_WARNING_PERIOD
from miro_gen.transport.events import DEFAULT_DEPTH, topic
from miro_gen.transport.events.frames import pack_batch
from miro_gen.transport.events.gaps import MAX_SOURCES

HERE = TESTS
HOST = HERE / "procs" / "channel_host.py"


def event(n: int) -> Miro.ExampleEventIDL:
    return Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), -float(n)))


@pytest.fixture
def naming() -> Iterator[NamingProcess]:
    n = NamingProcess()
    yield n
    n.stop()


class Host:
    """channel_host.py hosting `Events` in the context `robot`."""

    def __init__(self, naming: NamingProcess, *options: str) -> None:
        argv = [str(HOST), "--naming", naming.endpoint, "-MNC", "robot", *options, "Events"]
        self.proc = subprocess.Popen(
            [sys.executable, *argv],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "READY"


def test_channels_come_back_after_their_host_restarts(naming: NamingProcess) -> None:
    """Before: killed and restarted, the host bound new ports; consumers never received again
    (0 of ~5,000 events) and the old supplier counted its events as sent. Now both find the
    channel again, and what was pushed while it was gone counts as dropped."""
    host = Host(naming)
    supplier_side = RunningServer(naming.endpoint, "robot")
    consumer_side = RunningServer(naming.endpoint, "gui")
    try:
        supplier = StructuredPushSupplier(supplier_side.server.resolve_channel("robot/Events"))
        consumer = Recorder(consumer_side.server.resolve_channel("robot/Events"))
        consumer.set_subscriptions([("*", "ExampleEvent")])
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))
        supplier.push("ExampleEvent", event(0))
        eventually(lambda: len(consumer.events) == 1)

        host.proc.kill()
        host.proc.wait(10)
        eventually(lambda: not supplier.link.connected and not consumer.link.connected)
        sent, dropped = supplier.sent, supplier.dropped
        for n in range(1, 101):  # nobody is connected: these are lost, and counted
            assert supplier.push("ExampleEvent", event(n)) is True
        eventually(lambda: supplier.dropped == dropped + 100)
        assert supplier.sent == sent

        host = Host(naming)  # new ports; bound once the dead host's lease has ended
        eventually(lambda: supplier.link.connected and consumer.link.connected)
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))
        supplier.push("ExampleEvent", event(101))
        eventually(lambda: consumer.events[-1].payload == event(101))
        # (a link still connecting when a look-up finds the host's ipc:// twin may move twice)
        assert supplier.link.moves >= 1 and consumer.link.moves >= 1
    finally:
        consumer_side.stop()
        supplier_side.stop()
        host.proc.terminate()
        host.proc.wait(10)


def test_a_server_stops_its_channel_watcher_before_closing_its_sockets(
    naming: NamingProcess,
) -> None:
    """Before: a Server stopped while its channel watcher waited on the naming service closed
    the watcher's socket under it (ZeroMQ may abort the process then), and the watcher went
    on. Now the stop waits for the look-up under way, here on a frozen naming service."""
    host = Host(naming)
    side = RunningServer(naming.endpoint, "gui")
    try:
        consumer = Recorder(side.server.resolve_channel("robot/Events"))
        consumer.set_subscriptions([("*", "ExampleEvent")])
        eventually(lambda: consumer.link.connected)
        before = set(threading.enumerate())
        host.proc.kill()  # the link goes down: a watcher thread looks the channel up
        host.proc.wait(10)
        eventually(lambda: any(t.name == "miro-rematch" for t in watchers(before)))
        naming.proc.send_signal(signal.SIGSTOP)  # ... and now waits for an answer
        time.sleep(0.5)
        side.stop()
        assert not side.thread.is_alive()
        assert not [t for t in watchers(before) if t.is_alive()]
    finally:
        naming.proc.send_signal(signal.SIGCONT)
        side.stop()


def watchers(before: set[threading.Thread]) -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t not in before and t.name == "miro-rematch"]


def test_a_slow_consumer_keeps_the_newest_events_and_counts_the_rest(
    naming: NamingProcess,
) -> None:
    """Before: a slow consumer got events 11-23 s old, with missed = 0. Now it keeps the newest
    10 per topic (ROS 2's default) and counts what it skipped in `dropped`; latest-only keeps
    one. Every event is accounted for: received, dropped or missed. The consumers are held on
    their first event while the rest are pushed (slow for as long as the pushing lasts): with
    only their 20 ms per event, a loaded machine stretched the 1 kHz pushing until they kept up
    with a third of it (106 dropped of 300, at load 13)."""
    host = RunningServer(naming.endpoint, "r")
    listener = RunningServer(naming.endpoint, "slow")
    try:
        supplier = StructuredPushSupplier(EventChannelFactory(host.server).create_channel("Q"))
        remote = listener.server.resolve_channel("r/Q")
        gate = threading.Event()
        keep_last = Recorder(remote, delay=0.02, gate=gate, depth=DEFAULT_DEPTH)
        latest = Recorder(remote, delay=0.02, gate=gate, latest_only=True)
        for c in (keep_last, latest):
            c.set_subscriptions([("r", "ExampleEvent")])
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))
        time.sleep(0.3)
        total = 300
        supplier.push("ExampleEvent", event(0))
        eventually(lambda: keep_last.holding.is_set() or latest.holding.is_set(), 30)
        for n in range(1, total):  # 1 kHz, one event per frame, while they wait
            supplier.push("ExampleEvent", event(n))
            time.sleep(0.001)
        gate.set()  # and now they take 50 a second
        last = supplier._topics["ExampleEvent"].seq
        final = next(last) - 1  # the sequence number of the last event pushed

        def settled(c: Recorder) -> bool:
            return bool(c.events) and c.events[-1].seq == final and len(c.queue) == 0

        eventually(lambda: settled(keep_last) and settled(latest), 30)
        assert final == total - 1
        for c in (keep_last, latest):
            assert c.received + c.dropped + c.missed == total
            assert c.dropped > total / 2
            assert c.lag >= 0
        # What waited when pushing stopped: at most 10 (one for latest-only), then nothing.
        assert keep_last.received < total / 3 and latest.received < keep_last.received
    finally:
        listener.stop()
        host.stop()


def test_hz_shows_lag_and_missed_events(naming: NamingProcess) -> None:
    host = RunningServer(naming.endpoint, "r")
    hz = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "miro_gen.cli.main",
            "hz",
            "r/*",
            "--naming",
            naming.endpoint,
            "--channel",
            "r/H",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )
    try:
        supplier = StructuredPushSupplier(EventChannelFactory(host.server).create_channel("H"))
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))
        for n in range(50):
            supplier.push("ExampleEvent", event(n))
            time.sleep(0.01)
        time.sleep(1.5)
    finally:
        hz.send_signal(2)
        out, err = hz.communicate(timeout=20)
        host.stop()
    lines = [line for line in out.splitlines() if line.startswith("r/ExampleEvent:")]
    assert lines, (out, err)
    assert " lag " in lines[-1] and " ms (max " in lines[-1] and "  missed 0  " in lines[-1]


def test_spoofed_sequence_numbers_and_suppliers_stay_bounded(naming: NamingProcess) -> None:
    """Before: one spoofed sequence number set `missed` to 2^64, and every made-up supplier id
    stayed in the consumer's table. Now a jump beyond 2^24 is a restart, and the table holds
    at most MAX_SOURCES suppliers."""
    host = RunningServer(naming.endpoint, "r")
    listener = RunningServer(naming.endpoint, "c")
    try:
        channel = EventChannelFactory(host.server).create_channel("S")
        consumer = Recorder(listener.server.resolve_channel("r/S"))
        consumer.set_subscriptions([("*", "*")])
        rogue = zmq.Context.instance().socket(zmq.PUB)
        rogue.setsockopt(zmq.LINGER, 0)
        rogue.connect(channel.supplier_endpoint)
        time.sleep(0.5)
        data = event(1).serialize()
        head = topic("r", "ExampleEvent")
        type_hash = Miro.ExampleEventIDL._type_hash
        for seq in (0, 2**64 - 1, 1, 2**40, 2):  # one supplier, numbers all over the place
            rogue.send_multipart([head, pack_batch(7, type_hash, [(seq, 0, 0, data)])])
        eventually(lambda: len(consumer.events) == 5)
        assert consumer.missed == 0
        total = MAX_SOURCES + 500
        for start in range(0, total, 10):
            for supplier in range(start, min(start + 10, total)):
                rogue.send_multipart([head, pack_batch(supplier, type_hash, [(0, 0, 0, data)])])
            # a few frames at a time, each delivered before the next: no queue on the way
            # overflows, however slow the machine
            sent = min(start + 10, total)
            eventually(lambda n=sent: len(consumer.events) >= 5 + n, 30)

        def suppliers() -> int:
            return len({e.supplier for e in consumer.events})

        eventually(lambda: suppliers() > MAX_SOURCES, 30)
        assert len(consumer._gaps._next) <= MAX_SOURCES and consumer.missed == 0
        rogue.close()
    finally:
        listener.stop()
        host.stop()


def test_a_subscriber_that_never_reads_pins_a_bounded_amount(tmp_path: Path) -> None:
    """Before: the channel queued 10,000 frames of any size for each consumer, so one that
    never read pinned gigabytes inside the naming service hosting the channel. Now a queue
    holds QUEUE_BYTES_PER_PEER of frames of the largest size at most (16 here)."""
    naming = NamingProcess(options=("--channel", "Bulk"))
    supplier_side = RunningServer(naming.endpoint, "robot")
    try:
        channel = supplier_side.server.resolve_channel("Bulk")
        stuck = zmq.Context.instance().socket(zmq.SUB)
        stuck.setsockopt(zmq.LINGER, 0)
        stuck.setsockopt(zmq.RCVHWM, 1)
        stuck.setsockopt(zmq.RCVBUF, 4096)
        stuck.setsockopt(zmq.SUBSCRIBE, b"")
        stuck.connect(channel.consumer_endpoint)
        supplier = StructuredPushSupplier(channel)
        eventually(lambda: supplier.has_subscribers("Group"))
        points = [Miro.ExampleStructIDL(float(i), 0.0) for i in range(1 << 16)]  # 1 MiB
        group = Miro.ExampleGroupIDL(0, points)
        before = rss_mb(naming.proc.pid)
        pushed = 0
        for _ in range(300):  # 300 MiB that nobody reads
            pushed += supplier.push("Group", group)
            time.sleep(0.002)
        eventually(lambda: supplier.sent + supplier.dropped == pushed, 60)
        time.sleep(0.5)
        grown = rss_mb(naming.proc.pid) - before
        assert grown < 120, f"the channel's host grew by {grown:.0f} MiB"
        stuck.close()
    finally:
        supplier_side.stop()
        naming.stop()


def test_an_event_larger_than_a_message_is_a_counted_drop(naming: NamingProcess) -> None:
    host = RunningServer(naming.endpoint, "r")
    small = RunningServer(naming.endpoint, "small", "--max-message-size", "256K")
    try:
        supplier = StructuredPushSupplier(EventChannelFactory(small.server).create_channel("L"))
        consumer = Recorder(host.server.resolve_channel("small/L"))
        consumer.set_subscriptions([("*", "*")])
        eventually(lambda: supplier.has_subscribers("Group"))
        points = [Miro.ExampleStructIDL(float(i), 0.0) for i in range(1 << 15)]  # 512 KiB
        assert supplier.push("Group", Miro.ExampleGroupIDL(0, points)) is True
        assert supplier.dropped == 1 and supplier.sent == 0
        supplier.push("Group", Miro.ExampleGroupIDL(1, points[:10]))
        eventually(lambda: len(consumer.events) == 1)
        assert consumer.events[0].payload.c == 1
    finally:
        small.stop()
        host.stop()


def test_a_flood_of_bad_frames_is_two_warning_lines_with_counts(naming: NamingProcess) -> None:
    """Before: 20,000 malformed frames made a consumer print 10,000 warning lines. Now the
    first is a line, the rest are counted, and the count is said at the end of the period (or,
    here, when the consumer stops): 20,000 frames, two lines. A flood slower than the period
    (a loaded machine: 23 s with the test on one busy core) is one line more per period that
    ended during it, and the counts still add up to every frame."""
    host = RunningServer(naming.endpoint, "r")
    printer = HERE / "procs" / "event_printer.py"
    consumer = subprocess.Popen(
        [sys.executable, str(printer), "--naming", naming.endpoint, "r/Bad", "r/ExampleEvent"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )
    rogue = zmq.Context.instance().socket(zmq.PUB)
    type_hash = Miro.ExampleEventIDL._type_hash
    try:
        channel = EventChannelFactory(host.server).create_channel("Bad")
        assert consumer.stdout is not None
        assert consumer.stdout.readline().strip() == "READY"
        lines = _lines_of(consumer)
        rogue.setsockopt(zmq.LINGER, 0)
        rogue.connect(channel.supplier_endpoint)
        head = topic("r", "ExampleEvent")

        def marker(seq: int) -> None:
            """A good event, and its line from the consumer: what came before is handled."""
            rogue.send_multipart(
                [head, pack_batch(7, type_hash, [(seq, 0, 0, event(seq).serialize())])]
            )
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                if f'"seq": {seq},' in _next(lines, 0.2):
                    return
                if seq == 0:  # until the rogue's connection is up, send it again
                    rogue.send_multipart(
                        [head, pack_batch(7, type_hash, [(0, 0, 0, event(0).serialize())])]
                    )
            raise AssertionError(f"the consumer did not print event {seq}")

        marker(0)
        started = time.monotonic()  # before the first bad frame, so before the first line
        sent = 0
        # 10 bad frames, then a good one to wait for: no queue on the way overflows (the
        # channel's hold 16 frames of the largest size)
        for batch in range(1, 2001):
            for n in range(10):
                rogue.send_multipart([head, b"not a batch %d" % n])
            sent += 10
            marker(batch)
        consumer.send_signal(signal.SIGTERM)
        consumer.wait(30)
        took = time.monotonic() - started  # every line was written by now
        assert consumer.stderr is not None
        err = consumer.stderr.read()  # (its stdout is the reading thread's)
    finally:
        rogue.close()
        if consumer.poll() is None:
            consumer.kill()
            consumer.communicate()
        host.stop()
    warnings = [ln for ln in err.splitlines() if ln.startswith("[WARNING")]
    assert warnings[0].startswith("[WARNING MIRO] dropped an event frame on r/Bad: "), err[-3000:]
    summary = re.compile(
        r"\[WARNING MIRO\] ([0-9,]+) more like this in the last 10 s; the last: dropped an "
        r"event frame on r/Bad: "
    )
    counts = [summary.match(ln) for ln in warnings[1:]]
    assert counts and all(counts), err[-3000:]
    # One line at the end of each period that ended during the flood (none when it took less
    # than one: two lines in all), and one for the rest when the consumer stopped.
    assert len(counts) <= 1 + int(took // PEER_WARNING_PERIOD), (took, err[-3000:])
    assert sum(int(m.group(1).replace(",", "")) for m in counts if m) == sent - 1, err[-3000:]


def _lines_of(proc: subprocess.Popen[str]) -> queue.Queue[str]:
    """The lines of `proc`'s stdout, read by a thread of their own as they come."""
    lines: queue.Queue[str] = queue.Queue()
    assert proc.stdout is not None
    stdout = proc.stdout
    threading.Thread(target=lambda: [lines.put(ln) for ln in stdout], daemon=True).start()
    return lines


def _next(lines: queue.Queue[str], timeout: float) -> str:
    """The next line, or "" when none comes within `timeout` seconds."""
    try:
        return lines.get(timeout=timeout)
    except queue.Empty:
        return ""


def test_the_recorder_names_ten_made_up_types_and_counts_the_rest(
    naming: NamingProcess, tmp_path: Path
) -> None:
    """Before: events under 21,000 made-up type hashes made 21,000 warning lines when the
    recorder stopped. Now ten are named and the rest counted."""
    host = RunningServer(naming.endpoint, "r")
    output = tmp_path / "made-up.mcap"
    command = ["log", "record", "-o", str(output), "--naming", naming.endpoint]
    recorder = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", *command, "--channel", "r/Made"],
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )
    rogue = zmq.Context.instance().socket(zmq.PUB)
    try:
        channel = EventChannelFactory(host.server).create_channel("Made")
        assert recorder.stderr is not None
        assert recorder.stderr.readline().startswith("recording */* from ")
        rogue.setsockopt(zmq.LINGER, 0)
        rogue.connect(channel.supplier_endpoint)
        time.sleep(0.5)
        data = event(1).serialize()
        for n in range(300):
            made_up = n.to_bytes(4, "big").hex() * 8  # 32 bytes, no type has it
            rogue.send_multipart([topic("r", f"T{n}"), pack_batch(1, made_up, [(0, 0, 0, data)])])
            time.sleep(0.002)
        eventually(lambda: output.stat().st_size > 0 and _recorded(output) >= 0, 10)
        time.sleep(1.5)  # the last events into a closed chunk
        recorder.send_signal(signal.SIGINT)
        _, err = recorder.communicate(timeout=30)
    finally:
        rogue.close()
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate()
        host.stop()
    named = [ln for ln in err.splitlines() if "no generated type here has the type hash" in ln]
    counted = [ln for ln in err.splitlines() if "more topics or type hashes" in ln]
    assert len(named) == 10, err[-3000:]
    recorded = _recorded(output)
    assert recorded > 10, err[-3000:]
    assert counted == [
        f"miro log record: warning: {recorded - 10:,} more topics or type hashes without a "
        "generated type here, recorded without a schema"
    ]


def _recorded(path: Path) -> int:
    """Topics in the (finished) log."""
    from miro_gen.eventlog.reader import LogError, LogReader

    try:
        with LogReader(str(path)) as log:
            return len(log.topics())
    except LogError:
        return -1


def test_with_curve_a_process_without_the_key_cannot_call_publish_or_subscribe(
    tmp_path: Path,
) -> None:
    """Keys per robot or fleet: with `--keys`, every socket is CURVE; a process without the
    key, or with another one, is refused at the handshake, whether it calls, publishes or
    subscribes."""
    key = tmp_path / "fleet"
    other = tmp_path / "other"
    for k in (key, other):
        made = run_miro("keys", "new", str(k))
        assert made.returncode == 0, made.stderr
    assert (tmp_path / "fleet.key_secret").stat().st_mode & 0o077 == 0
    secret = str(key) + ".key_secret"
    naming = NamingProcess(options=("--keys", secret, "--channel", "Secure"))
    robot = RunningServer(naming.endpoint, "robot", "--keys", secret)
    gui = RunningServer(naming.endpoint, "gui", "--keys", secret)
    try:
        channel = robot.server.resolve_channel("Secure")
        supplier = StructuredPushSupplier(channel)
        consumer = Recorder(gui.server.resolve_channel("Secure"))
        consumer.set_subscriptions([("*", "*")])
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))

        # A stranger on the same network, without the key or with another one.
        for args in ([], ["--keys", str(other)]):
            stranger = Client(["t", "--naming", naming.endpoint, *args], context=zmq.Context())
            with pytest.raises(TRANSIENT, match="refused the connection"):
                stranger.naming.registry.resolve("Secure")
            stranger.close()
        ctx = zmq.Context()
        spoofer = ctx.socket(zmq.PUB)  # publishes into the channel, in the clear
        listener = ctx.socket(zmq.SUB)  # listens to it, in the clear
        for s in (spoofer, listener):
            s.setsockopt(zmq.LINGER, 0)
        listener.setsockopt(zmq.SUBSCRIBE, b"")
        spoofer.connect(channel.supplier_endpoint)
        listener.connect(channel.consumer_endpoint)
        time.sleep(0.5)
        data = event(666).serialize()
        for _ in range(5):
            spoofer.send_multipart(
                [
                    topic("robot", "ExampleEvent"),
                    pack_batch(1, Miro.ExampleEventIDL._type_hash, [(0, 0, 0, data)]),
                ]
            )
        supplier.push("ExampleEvent", event(1))
        eventually(lambda: len(consumer.events) == 1)
        time.sleep(0.3)
        assert [e.payload for e in consumer.events] == [event(1)]  # nothing of the spoofer's
        assert not listener.poll(200)  # and the eavesdropper heard nothing
        ctx.destroy(0)
        keyed = Client(["t", "--naming", naming.endpoint, "--keys", secret], context=zmq.Context())
        assert keyed.naming.registry.resolve("Secure").name == "Secure"
        keyed.close()
    finally:
        gui.stop()
        robot.stop()
        naming.stop()


def test_binding_beyond_loopback_needs_a_key_or_insecure(tmp_path: Path) -> None:
    env = service_env(HOME=str(tmp_path))  # no default key
    env.pop("MIRO_KEYS", None)
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint", "tcp://0.0.0.0:0"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert done.returncode == 2
    assert "binds 0.0.0.0, beyond this machine" in done.stderr and "--insecure" in done.stderr
    insecure = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "miro_gen.cli.main",
            "naming",
            "--endpoint",
            "tcp://0.0.0.0:0",
            "--insecure",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert insecure.stdout is not None and insecure.stderr is not None
    line = insecure.stdout.readline()
    insecure.terminate()
    insecure.wait(10)
    assert "--insecure: in the clear, open to anyone who can reach it" in line
    assert insecure.stderr.readline().startswith(  # what it opens, precisely
        "[WARNING MIRO] --insecure: serving on every interface (0.0.0.0) with neither key nor "
        "encryption: anyone who can reach this machine may list, resolve and bind names, and "
        "publish and subscribe on its event channels, and anyone on the network between may "
        "read and change what is said"
    )
