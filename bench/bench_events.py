"""Benchmark: typed events through an event channel against a raw pyzmq XSUB/XPUB proxy, and
against Eclipse Zenoh's pub/sub, with the same payload in the same run.

    python bench/bench_events.py [--events N] [--check]

Every payload is the CDR encoding of a Miro::ExampleEventIDL (28 bytes). Each supplier runs in a
process of its own on loopback; the consumer runs in this process and counts in a Python callback:
- raw pyzmq: a PUB socket sends [topic, payload] messages to an XSUB/XPUB proxy (`zmq.proxy` in a
  thread of the supplier's process, as our channel host runs it) and a SUB socket receives them;
- miro-gen: `StructuredPushSupplier.push("ExampleEvent", Miro.ExampleEventIDL(...))` into a
  channel hosted by `EventChannelFactory(server).create_channel()` in the supplier's process, to a
  `StructuredPushConsumer` whose `push_structured_event` reads the decoded `event.payload`;
- Zenoh (if `eclipse-zenoh` is installed): two peers on loopback (multicast scouting off,
  explicit listen and connect endpoints), a publisher (congestion control BLOCK) and a subscriber
  callback.

Throughput: the supplier pushes N events as fast as it can; the figure is the consumer's rate
between its first and its last event, and what was lost is counted (sequence numbers for
miro-gen, sent minus received for the others). When a run loses events, the supplier then paces
itself (sleeping between slices of 64 events so as to keep to a target rate), starting at 90%
of the delivered rate and 10% lower each time, until a run loses nothing; both runs are printed.
Target (issue 4): miro-gen's lossless rate is at least 0.5x the best raw pyzmq delivers (its
flat-out rate, losses and all). `--check` exits 1 when it is missed.

Latency: 200 single events at 100 Hz, p50 and p99 from push to the callback (the payload
carries the monotonic clock), miro-gen against raw pyzmq and Zenoh: batching must not add
latency at low rates. miro-gen's push() runs either in a thread of its own (the event then waits
for the reactor thread) or in a reactor timer, as services publish (ExampleC).

Large events (camera images of 1 MB and 6 MB to consumer processes, against raw pyzmq and
Zenoh; 6 MB at 30 Hz to 4 consumers; a recorded camera and laser stream played back by `miro
log play`): see bench/events_large.py, run after the above (`--large-only`, `--small-only`).

The machine's other load shows in every figure: compare the rows of one run, not runs.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import events_large  # noqa: E402 - beside this file
import Miro  # noqa: E402
import zmq  # noqa: E402
from raw_peers import free_port, zenoh_config  # noqa: E402 - beside this file

TARGET = 0.5
TOPIC = b"bench\0ExampleEvent\0"
EVENT = "ExampleEvent"
LATENCY_EVENTS = 200
LATENCY_HZ = 100.0

try:
    import zenoh
except ImportError:  # optional: pip install miro-gen[bench]
    zenoh = None


def payload(counter: int, stamp: float = 0.0) -> Miro.ExampleEventIDL:
    return Miro.ExampleEventIDL(counter, Miro.ExampleStructIDL(stamp, 1.0))


# ---- supplier processes ---------------------------------------------------------------------
# A supplier prints "READY <where>", then for each "RUN <count> <rate>" line on stdin pushes
# `count` events (at `rate` per second; 0: as fast as it can) and prints "SENT <count>".
# "LATENCY <count> <hz>" pushes events one at a time carrying the monotonic clock.


def paced(count: int, rate: float, send: Callable[[int], object]) -> None:
    """send(i) for i < count, keeping to `rate` events per second (0: flat out)."""
    start = time.monotonic()
    for i in range(count):
        if rate and not i & 63:
            ahead = i / rate - (time.monotonic() - start)
            if ahead > 0:
                time.sleep(ahead)
        send(i)


def serve_commands(
    send: Callable[[int], object],
    send_stamped: Callable[[int], object],
    on_timer: Callable[[int, float], None] | None = None,
    dropped: Callable[[], int] = lambda: 0,
) -> None:
    for line in sys.stdin:
        cmd, *args = line.split()
        if cmd == "RUN":
            count, rate = int(args[0]), float(args[1])
            start = time.monotonic()
            paced(count, rate, send)
            print("SENT", count, time.monotonic() - start, dropped(), flush=True)
        elif cmd == "LATENCY":
            count, hz = int(args[0]), float(args[1])
            for i in range(count):
                time.sleep(1 / hz)
                send_stamped(i)
            print("SENT", count, 0, dropped(), flush=True)
        elif cmd == "LATENCY_TIMER" and on_timer is not None:
            on_timer(int(args[0]), float(args[1]))
            print("SENT", args[0], 0, dropped(), flush=True)
        else:
            return


def raw_supplier() -> None:
    ctx = zmq.Context()
    xsub, xpub = ctx.socket(zmq.XSUB), ctx.socket(zmq.XPUB)
    for s in (xsub, xpub):
        s.setsockopt(zmq.LINGER, 0)
    port_in = xsub.bind_to_random_port("tcp://127.0.0.1")
    port_out = xpub.bind_to_random_port("tcp://127.0.0.1")
    threading.Thread(target=zmq.proxy, args=(xsub, xpub), daemon=True).start()
    pub = ctx.socket(zmq.PUB)
    pub.setsockopt(zmq.LINGER, 0)
    pub.connect(f"tcp://127.0.0.1:{port_in}")
    data = payload(0).serialize()
    print("READY", f"tcp://127.0.0.1:{port_out}", flush=True)

    def send(i: int) -> None:
        pub.send_multipart([TOPIC, data])

    def send_stamped(i: int) -> None:
        pub.send_multipart([TOPIC, payload(i, time.monotonic()).serialize()])

    serve_commands(send, send_stamped)


def ours_supplier(naming: str) -> None:
    from miro_gen import EventChannelFactory, Server, StructuredPushSupplier

    server = Server(["bench", "--naming", naming, "-MNC", "bench"])
    channel = EventChannelFactory(server).create_channel("Events")
    supplier = StructuredPushSupplier(channel)
    threading.Thread(target=server.run, daemon=True).start()
    print("READY", channel.name, flush=True)
    value = payload(0)

    def send(i: int) -> None:
        value.counter = i
        supplier.push(EVENT, value)

    def send_stamped(i: int) -> None:
        supplier.push(EVENT, payload(i, time.monotonic()))

    def on_timer(count: int, hz: float) -> None:
        """Push from a reactor timer, as services do (ExampleC): no hand-over between threads."""
        done = threading.Event()
        sent = itertools.count()

        def tick(_: object) -> None:
            i = next(sent)
            if i < count:
                send_stamped(i)
            else:
                done.set()

        timer = server.reactor().schedule_timer(1 / hz, 1 / hz, tick)
        done.wait()
        server.reactor().cancel_timer(timer)

    deadline = time.monotonic() + 10
    while not supplier.has_subscribers(EVENT) and time.monotonic() < deadline:
        time.sleep(0.01)
    serve_commands(send, send_stamped, on_timer, lambda: supplier.dropped)
    server.shutdown()


def zenoh_supplier(port: str) -> None:
    session = zenoh.open(zenoh_config(f"tcp/127.0.0.1:{port}", None))
    pub = session.declare_publisher(
        "bench/ExampleEvent", congestion_control=zenoh.CongestionControl.BLOCK
    )
    data = payload(0).serialize()
    print("READY", port, flush=True)
    serve_commands(
        lambda i: pub.put(data),
        lambda i: pub.put(payload(i, time.monotonic()).serialize()),
    )
    session.close()


# ---- the consumer side (this process) -------------------------------------------------------


class Counter:
    """What the consumer's callback records in one run."""

    def __init__(self) -> None:
        self.received = 0
        self.first = self.last = 0.0
        self.latencies: list[float] = []

    def hit(self) -> None:
        now = time.monotonic()
        if not self.received:
            self.first = now
        self.last = now
        self.received += 1

    def stamped(self, data: bytes) -> None:
        sent = Miro.ExampleEventIDL.deserialize(data).data.a
        self.latencies.append(time.monotonic() - sent)

    def rate(self) -> float:
        span = self.last - self.first
        return (self.received - 1) / span if span > 0 else 0.0


class Supplier:
    """A supplier process driven through its stdin and stdout."""

    def __init__(self, role: str, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--role", role, *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.where = self._line("READY")
        self.pushing = 0.0
        self.dropped = 0

    def _line(self, word: str) -> str:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith(word):
            raise RuntimeError(f"supplier said {line!r}, expected {word}")
        return line.split(maxsplit=1)[1].strip()

    def command(self, *words: object) -> int:
        """Send a command; how many events the supplier pushed (and `self.pushing`: how many
        seconds its push loop took; `self.dropped`: how many events it has dropped so far)."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(" ".join(map(str, words)) + "\n")
        self.proc.stdin.flush()
        count, seconds, dropped = self._line("SENT").split()
        self.pushing = float(seconds)
        self.dropped = int(dropped)
        return int(count)

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def settle(counter: Counter, expected: int, quiet: float = 0.5) -> None:
    """Wait until `expected` events arrived, or none for `quiet` seconds."""
    seen, since = -1, time.monotonic()
    while counter.received < expected:
        if counter.received != seen:
            seen, since = counter.received, time.monotonic()
        elif time.monotonic() - since > quiet:
            return
        time.sleep(0.005)


class Result:
    def __init__(self, name: str, rate: float, lost: int, note: str = "") -> None:
        self.name, self.rate, self.lost, self.note = name, rate, lost, note


class Latency:
    def __init__(self, name: str, samples: list[float]) -> None:
        s = sorted(samples)
        self.name = name
        self.p50 = statistics.median(s) if s else float("nan")
        self.p99 = s[max(0, int(len(s) * 0.99) - 1)] if s else float("nan")
        self.lost = LATENCY_EVENTS - len(s)


class Bench:
    """One transport's consumer, plugged into a counter the runs reset."""

    name = ""

    def __init__(self) -> None:
        self.counter = Counter()
        self.stamped = False

    def on_event(self, data: bytes) -> None:
        if self.stamped:
            self.counter.stamped(data)
        self.counter.hit()

    def missed(self) -> int | None:
        """Events the consumer knows it lost (None: it cannot tell; sent - received is used)."""
        return None

    def run(self, count: int, rate: float) -> tuple[int, Counter, int]:
        """(sent, counter, lost) of one run."""
        self.counter = Counter()
        base = self.missed()
        sent = self.supplier.command("RUN", count, rate)
        settle(self.counter, sent)
        known = self.missed()
        lost = sent - self.counter.received if known is None else known - (base or 0)
        return sent, self.counter, max(lost, sent - self.counter.received)

    def warm_up(self) -> None:
        for _ in range(50):
            self.counter = Counter()
            self.supplier.command("RUN", 1000, 20_000)
            settle(self.counter, 1000, 0.2)
            if self.counter.received == 1000:
                return
        raise RuntimeError(f"{self.name}: events do not arrive")

    def throughput(self, count: int) -> list[Result]:
        """The flat-out run; if it lost events, then the paced run that lost none."""
        self.warm_up()
        dropped = self.supplier.dropped
        _, c, lost = self.run(count, 0)
        dropped = self.supplier.dropped - dropped
        note = f"flat out, the supplier dropped {dropped}" if dropped else "flat out"
        flat = Result(self.name, c.rate(), lost, note)
        if not lost:
            return [flat]
        rate = flat.rate
        for _ in range(20):
            rate *= 0.9
            _, c, lost = self.run(count, rate)
            if not lost:
                break
        return [flat, Result(self.name, c.rate(), lost, f"paced to {rate:,.0f}/s")]

    def latency(self, command: str = "LATENCY", name: str = "") -> Latency:
        self.warm_up()
        self.counter = Counter()
        self.stamped = True
        self.supplier.command(command, LATENCY_EVENTS, LATENCY_HZ)
        settle(self.counter, LATENCY_EVENTS)
        self.stamped = False
        return Latency(name or self.name, self.counter.latencies)

    def latencies(self) -> list[Latency]:
        return [self.latency()]

    supplier: Supplier

    def close(self) -> None:
        self.supplier.close()


class RawBench(Bench):
    name = "raw pyzmq XSUB/XPUB proxy"

    def __init__(self) -> None:
        super().__init__()
        self.supplier = Supplier("raw")
        self.ctx = zmq.Context()
        self.sub = self.ctx.socket(zmq.SUB)
        self.sub.setsockopt(zmq.LINGER, 0)
        self.sub.setsockopt(zmq.SUBSCRIBE, TOPIC)
        self.sub.connect(self.supplier.where)
        self.stop = False
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        poller = zmq.Poller()
        poller.register(self.sub, zmq.POLLIN)
        recv, on_event = self.sub.recv_multipart, self.on_event
        while not self.stop:
            if poller.poll(100):
                while True:
                    try:
                        parts = recv(zmq.NOBLOCK)
                    except zmq.Again:
                        break
                    on_event(parts[1])

    def close(self) -> None:
        super().close()
        self.stop = True
        self.thread.join()
        self.sub.close()
        self.ctx.term()


class OursBench(Bench):
    name = "miro-gen event channel"

    def __init__(self) -> None:
        from miro_gen import Server, StructuredEvent, StructuredPushConsumer

        super().__init__()
        endpoint = f"tcp://127.0.0.1:{free_port()}"
        self.naming = subprocess.Popen(
            [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint", endpoint],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.naming.stdout is not None
        self.naming.stdout.readline()
        self.supplier = Supplier("ours", endpoint)
        self.server = Server(["bench", "--naming", endpoint, "-MNC", "consumer"])
        bench = self

        class Consumer(StructuredPushConsumer):
            def push_structured_event(self, event: StructuredEvent) -> None:
                value = event.payload
                if bench.stamped:
                    bench.counter.latencies.append(time.monotonic() - value.data.a)
                bench.counter.hit()

        # Every event, as the raw consumer gets it (a default consumer keeps the newest 10).
        self.consumer = Consumer(self.server.resolve_channel(self.supplier.where), depth=0)
        self.consumer.set_subscriptions([("bench", EVENT)])
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()

    def missed(self) -> int | None:
        return self.consumer.missed

    def latencies(self) -> list[Latency]:
        return [
            self.latency("LATENCY", "miro-gen, push() from a thread"),
            self.latency("LATENCY_TIMER", "miro-gen, push() from a timer"),
        ]

    def close(self) -> None:
        super().close()
        self.server.shutdown()
        self.thread.join()
        self.naming.kill()
        self.naming.wait()


class ZenohBench(Bench):
    name = "Zenoh pub/sub (peer)"

    def __init__(self) -> None:
        super().__init__()
        port = str(free_port())
        self.supplier = Supplier("zenoh", port)
        self.session = zenoh.open(zenoh_config(None, f"tcp/127.0.0.1:{port}"))
        self.sub = self.session.declare_subscriber(
            "bench/ExampleEvent", lambda sample: self.on_event(sample.payload.to_bytes())
        )

    def close(self) -> None:
        super().close()
        self.sub.undeclare()
        self.session.close()


def measure(make: Callable[[], Bench], count: int) -> tuple[list[Result], list[Latency]]:
    bench = make()
    try:
        return bench.throughput(count), bench.latencies()
    finally:
        bench.close()


def lossless(results: list[Result]) -> float:
    """The rate of the run that lost nothing (0 if none)."""
    return max((r.rate for r in results if not r.lost), default=0.0)


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--events", type=int, default=300_000, help="events per throughput run")
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    ap.add_argument(
        "--large-events",
        type=int,
        default=1000,
        help="large events per run, at least (1000; runs last about 2 s)",
    )
    ap.add_argument(
        "--repeat", type=int, default=5, help="interleaved rounds of large-event runs (median; 5)"
    )
    only = ap.add_mutually_exclusive_group()
    only.add_argument("--small-only", action="store_true", help="skip the large events")
    only.add_argument("--large-only", action="store_true", help="only the large events")
    ap.add_argument("--role", help=argparse.SUPPRESS)
    ap.add_argument("where", nargs="*", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role in events_large.ROLES:
        events_large.ROLES[args.role](*args.where)
        return 0
    if args.role:
        where = args.where[0] if args.where else ""
        {"raw": raw_supplier, "ours": lambda: ours_supplier(where)}.get(
            args.role, lambda: zenoh_supplier(where)
        )()
        return 0
    small_ok = True if args.large_only else small_events(args)
    large_ok = True
    if not args.small_only:
        print()
        large_ok = events_large.main(args.large_events, args.repeat)
    return 1 if args.check and not (small_ok and large_ok) else 0


def small_events(args: argparse.Namespace) -> bool:
    """The 28-byte events: throughput and latency; whether the target is met."""
    raw, lats = measure(RawBench, args.events)
    ours, ours_lats = measure(OursBench, args.events)
    raw_lat = lats[0]
    rows, lats = raw + ours, lats + ours_lats
    z: list[Result] = []
    if zenoh is not None:
        z, z_lats = measure(ZenohBench, args.events)
        rows += z
        lats += z_lats
    print(f"{'throughput, 28-byte events':30} {'events/s':>11} {'lost':>7}  run")
    for r in rows:
        print(f"{r.name:30} {r.rate:11,.0f} {r.lost:7}  {r.note}")
    if zenoh is None:
        print("zenoh: skipped (eclipse-zenoh not installed)")
    print(f"\n{'latency, single events at 100 Hz':34} {'p50 us':>8} {'p99 us':>8} {'lost':>5}")
    for lat in lats:
        print(f"{lat.name:34} {lat.p50 * 1e6:8.1f} {lat.p99 * 1e6:8.1f} {lat.lost:5}")
    print()
    # Raw pyzmq's best: what it delivered flat out, losses and all; ours: only without loss.
    raw_best, ours_best = max(r.rate for r in raw), lossless(ours)
    ratio = ours_best / raw_best
    verdict = "ok" if ratio >= TARGET else "MISSED"
    print(
        f"throughput miro-gen (no loss) / raw pyzmq (best delivered): {ratio:.2f} "
        f"(target >= {TARGET}: {verdict})"
    )
    for lat in ours_lats:
        print(f"p50 latency {lat.name} / raw pyzmq: {lat.p50 / raw_lat.p50:.2f}")
    if z:
        z_best = lossless(z) or max(r.rate for r in z)
        print(f"throughput raw pyzmq / Zenoh: {raw_best / z_best:.2f}")
        print(f"throughput miro-gen / Zenoh: {ours_best / z_best:.2f}")
        for lat in ours_lats:
            print(f"p50 latency {lat.name} / Zenoh: {lat.p50 / lats[-1].p50:.2f}")
    return ratio >= TARGET


if __name__ == "__main__":
    sys.exit(main())
