"""Benchmark: events through an event channel's Notification door (CosNotifyChannelAdmin),
between C++ omniORB peers written as Miro's suppliers and consumers and Python services, against
omniORB's own C++ supplier and consumer through the same door, and against the ZeroMQ door.

    python bench/bench_notify.py [--events N] [--size BYTES] [--rounds R] [--check]

One `miro naming --iiop-endpoint --channel bench/EventChannel` hosts the channel (both doors).
Events are `NotifyBench::Sample` (tests/corba/NotifyBench.idl: a time stamp, a number, padding
to SIZE bytes of CDR, 100 by default), domain `bench`, type `Sample`. Four paths, each a
supplier and a consumer in processes of their own:

    cpp -> cpp      C++ supplier, Notification door, C++ consumer (omniORB's own, the baseline)
    cpp -> python   C++ supplier, Notification door, then ZeroMQ to a Python consumer
    python -> cpp   Python supplier, ZeroMQ, then the Notification door to a C++ consumer
    python -> python  the ZeroMQ door alone

Throughput: the supplier pushes N events as fast as it may; the consumer's rate is the events it
received over the time from its first to its last (a consumer that falls behind loses the
oldest: the count received is printed too). Latency: p50 of (received - pushed) over 2000
events pushed at 1000/s, each path alone. The paths alternate in rounds so that the machine's
changing load falls on all alike; each figure is the median of the rounds (with min-max), and
the load average is printed. Goal (issue 27): the Python consumer at least 0.5x the C++
consumer's rate at 100-byte events (`--check` exits 1 when it misses). Needs what the CORBA tests
need (omniNames is not used), g++ and libcos4-dev.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]

from corba_peers import CORBA, build_notify_peer, notify_tools_missing, readline  # noqa: E402
from loopback import free_port  # noqa: E402

GOAL = 0.5
DOMAIN = "bench"
PATHS = ("cpp -> cpp", "cpp -> python", "python -> cpp", "python -> python")
LATENCY_EVENTS, LATENCY_RATE = 2000, 1000


# ---- the Python roles (run as processes of their own: `bench_notify.py --role ...`) ---------


def role_consumer(naming: str, n: int) -> None:
    from miro_gen import Server
    from miro_gen.transport.events import KEEP_ALL, StructuredPushConsumer

    server = Server(["consumer", "--naming", naming, "-MNC", DOMAIN])
    channel = server.resolve_channel("EventChannel")
    latencies: list[float] = []
    stamps: list[float] = []

    class Counter(StructuredPushConsumer):
        def push_structured_event(self, event: object) -> None:
            now = time.time_ns()
            stamps.append(time.perf_counter())
            latencies.append((now - event.payload.sent_ns) / 1000)  # type: ignore[attr-defined]

    Counter(channel, depth=KEEP_ALL).set_subscriptions([(DOMAIN, "Sample")])

    def check(_: object) -> None:
        if len(stamps) >= n or (stamps and time.perf_counter() - stamps[-1] > 3):
            server.shutdown()

    server.reactor().schedule_timer(0.05, 0.05, check, None)
    server.reactor().call_soon(lambda: print("CONNECTED", flush=True))
    server.run()
    secs = stamps[-1] - stamps[0] if stamps else 0.0
    p50 = statistics.median(latencies) if latencies else 0.0
    print(f"GOT {len(stamps)} {secs:.6f} {p50:.1f}", flush=True)


def role_supplier(naming: str, n: int, size: int, rate: int) -> None:
    import NotifyBench

    from miro_gen import Server
    from miro_gen.transport.events import StructuredPushSupplier

    server = Server(["supplier", "--naming", naming, "-MNC", DOMAIN])
    supplier = StructuredPushSupplier(server.resolve_channel("EventChannel"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not supplier.has_subscribers("Sample"):
        time.sleep(0.01)
    print("READY", flush=True)
    sys.stdin.readline()
    pad = bytes(range(256)) * (max(0, size - 16) // 256 + 1)
    sample = NotifyBench.Sample(0, 0, pad[: max(0, size - 16)])
    t0 = time.perf_counter()
    for i in range(n):
        if rate:
            while time.perf_counter() < t0 + i / rate:
                time.sleep(0.0002)
        sample.sent_ns = time.time_ns()
        sample.seq = i
        supplier.push("Sample", sample)
    print(f"SENT {n} {time.perf_counter() - t0:.6f}", flush=True)
    sys.stdin.read()
    server.shutdown()
    thread.join(10)


# ---- the harness --------------------------------------------------------------------------------


class Bench:
    def __init__(self, peer: Path, gen: Path) -> None:
        self.peer = peer
        self.env = dict(os.environ)
        self.env["PYTHONPATH"] = os.pathsep.join([str(gen), str(ROOT / "generated"), str(ROOT)])
        zmq_port, iiop_port = free_port(), free_port()
        self.naming = f"tcp://127.0.0.1:{zmq_port}"
        self.cpp_naming = f"NameService=corbaloc::127.0.0.1:{iiop_port}/NameService"
        self.host = subprocess.Popen(
            [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint", self.naming,
             "--iiop-endpoint", f"127.0.0.1:{iiop_port}", "--channel",
             f"{DOMAIN}/EventChannel", "--log-file", "none", "-MLL", "3"],
            stdout=subprocess.PIPE, text=True, env=self.env,
        )  # fmt: skip
        assert self.host.stdout is not None
        while not readline(self.host.stdout, 30, "miro naming").startswith("event channel"):
            pass

    def consumer(self, lang: str, n: int) -> subprocess.Popen[str]:
        if lang == "cpp":
            cmd = [str(self.peer), "bench-consume", str(n), "-MNC", DOMAIN,
                   "-ORBInitRef", self.cpp_naming]  # fmt: skip
        else:
            cmd = [sys.executable, __file__, "--role", "consumer", "--naming", self.naming,
                   "--events", str(n)]  # fmt: skip
        proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=self.env
        )
        assert proc.stdout is not None
        line = readline(proc.stdout, 60, f"the {lang} consumer")
        while not line.startswith("CONNECTED"):
            line = readline(proc.stdout, 60, f"the {lang} consumer")
        return proc

    def supplier(self, lang: str, n: int, size: int, rate: int) -> subprocess.Popen[str]:
        if lang == "cpp":
            cmd = [str(self.peer), "bench-supply", str(n), str(size), str(rate), "-MNC", DOMAIN,
                   "-ORBInitRef", self.cpp_naming]  # fmt: skip
        else:
            cmd = [sys.executable, __file__, "--role", "supplier", "--naming", self.naming,
                   "--events", str(n), "--size", str(size), "--rate", str(rate)]  # fmt: skip
        proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=self.env
        )
        assert proc.stdout is not None
        while not readline(proc.stdout, 60, f"the {lang} supplier").startswith("READY"):
            pass
        return proc

    def run(self, path: str, n: int, size: int, rate: int = 0) -> tuple[float, int, float]:
        """(events/s received, events received, p50 latency in microseconds) of one path."""
        source, _, sink = path.split()
        consumer = self.consumer(sink, n)
        supplier = self.supplier(source, n, size, rate)
        assert supplier.stdin is not None and consumer.stdout is not None
        try:
            supplier.stdin.write("go\n")
            supplier.stdin.flush()
            line = readline(consumer.stdout, 600, f"the {sink} consumer")
            while not line.startswith("GOT"):
                line = readline(consumer.stdout, 600, f"the {sink} consumer")
            _, got, secs, p50 = line.split()
            return int(got) / max(float(secs), 1e-9), int(got), float(p50)
        finally:
            for proc in (supplier, consumer):
                try:
                    proc.communicate("", timeout=30)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.communicate(timeout=10)

    def close(self) -> None:
        self.host.terminate()
        self.host.wait(10)


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):10.0f}  ({min(values):.0f}-{max(values):.0f})"


def main() -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--events", type=int, default=40_000, help="events per throughput run")
    p.add_argument("--size", type=int, default=100, help="bytes of an event's CDR (100)")
    p.add_argument("--rounds", type=int, default=5, help="rounds of each path (default 5)")
    p.add_argument("--check", action="store_true", help=f"exit 1 below {GOAL}x")
    p.add_argument("--role", choices=("consumer", "supplier"), help=argparse.SUPPRESS)
    p.add_argument("--naming", help=argparse.SUPPRESS)
    p.add_argument("--rate", type=int, default=0, help=argparse.SUPPRESS)
    ns = p.parse_args()
    if ns.role == "consumer":
        role_consumer(ns.naming, ns.events)
        return 0
    if ns.role == "supplier":
        role_supplier(ns.naming, ns.events, ns.size, ns.rate)
        return 0
    missing = notify_tools_missing()
    if missing:
        print(f"bench_notify: needs {', '.join(missing)}", file=sys.stderr)
        return 2
    peer = build_notify_peer()
    gen = Path(tempfile.mkdtemp(prefix="bench-notify-"))
    subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.idl", "-o", str(gen), str(CORBA / "NotifyBench.idl")],
        check=True, cwd=ROOT, capture_output=True,
    )  # fmt: skip
    sys.path.insert(0, str(gen))
    bench = Bench(peer, gen)
    rates: dict[str, list[float]] = {path: [] for path in PATHS}
    counts: dict[str, list[int]] = {path: [] for path in PATHS}
    latencies: dict[str, list[float]] = {path: [] for path in PATHS}
    loads = []
    try:
        for _ in range(ns.rounds):
            for path in PATHS:
                loads.append(os.getloadavg()[0])
                rate, got, _ = bench.run(path, ns.events, ns.size)
                rates[path].append(rate)
                counts[path].append(got)
                _, _, p50 = bench.run(path, LATENCY_EVENTS, ns.size, LATENCY_RATE)
                latencies[path].append(p50)
    finally:
        bench.close()
    print(f"{ns.size}-byte events, {ns.events} per run, {ns.rounds} rounds; load average "
          f"{min(loads):.1f}-{max(loads):.1f} (2 cores)")  # fmt: skip
    print(f"{'path':18} {'events/s (median, min-max)':>30} {'received':>10} {'p50 us':>10}")
    for path in PATHS:
        got = int(statistics.median(counts[path]))
        p50 = statistics.median(latencies[path])
        print(f"{path:18} {spread(rates[path]):>30} {got:>10} {p50:10.0f}")
    base = statistics.median(rates["cpp -> cpp"])
    ratio = statistics.median(rates["cpp -> python"]) / base
    print(f"Python consumer / C++ consumer (C++ supplier, Notification door): {ratio:.2f}x "
          f"(goal: at least {GOAL}x)")  # fmt: skip
    from_python = statistics.median(rates["python -> cpp"]) / base
    zmq_alone = statistics.median(rates["python -> python"]) / base
    print(f"C++ consumer of a Python supplier / of a C++ supplier: {from_python:.2f}x; "
          f"ZeroMQ door alone / Notification door: {zmq_alone:.2f}x")  # fmt: skip
    return 1 if ns.check and ratio < GOAL else 0


if __name__ == "__main__":
    sys.exit(main())
