"""Benchmark: does `miro log record` keep up with 20,000 small events per second?

    python bench/bench_record.py [--rate 20000] [--seconds 5] [--check]

A naming service hosts the channel; a supplier process pushes ExampleEvents (28-byte CDR
payloads) paced at --rate for --seconds. Two rows, each with the same supplier run: a raw pyzmq
SUB that only counts the events in each frame (the baseline: what the channel delivers), and
`miro log record` writing the MCAP file, whose events are then counted in the file with the
mcap reader and checked for sequence gaps. Both print events received, lost, the rate achieved
and the CPU time the receiving process used. Target (issue 7): the recorder loses nothing at
20,000 events/s; `--check` exits 1 when it does.

Then replay spacing: a log of 60 events with gaps of 10, 30 and 5 ms is played at 1x by
`miro log play` into a consumer process (tests/procs/event_printer.py); printed: how far each
arrival strays from the recorded spacing (arrival minus log time, against the median of that
offset), the median and the 95th percentile, in ms (the first two events are left out: the
consumer imports the event's module on the first). On an idle machine: within 5 ms for 95 %.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "generated"), str(ROOT)]))
TARGET = 20_000
MIRO = [sys.executable, "-m", "miro_gen.cli.main"]
PRINTER = ROOT / "tests" / "procs" / "event_printer.py"  # a consumer printing arrival times

SUPPLIER = """
import sys, time
import Miro
from miro_gen import Server, StructuredPushSupplier
import threading
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "bench"])
rate, seconds = float(sys.argv[2]), float(sys.argv[3])
supplier = StructuredPushSupplier(server.resolve_channel("EventChannel"))
threading.Thread(target=server.run, daemon=True).start()
while not supplier.has_subscribers("ExampleEvent"):
    time.sleep(0.01)
time.sleep(0.5)
total = int(rate * seconds)
event = Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, 2.0))
start = time.monotonic()
sent = 0
while sent < total:  # bursts every millisecond, as many as the rate asks for by now
    due = min(total, int((time.monotonic() - start) * rate) + 1)
    while sent < due:
        supplier.push("ExampleEvent", event)
        sent += 1
    time.sleep(0.001)
elapsed = time.monotonic() - start
time.sleep(1.0)
print(sent, elapsed, flush=True)
server.shutdown()
"""

RAW_COUNTER = """
import signal, sys, zmq
ctx = zmq.Context()
s = ctx.socket(zmq.SUB)
s.setsockopt(zmq.RCVHWM, 100000)
s.setsockopt(zmq.SUBSCRIBE, b"")
s.connect(sys.argv[1])
print("READY", flush=True)
signal.signal(signal.SIGINT, lambda *_: (print(count, missed, flush=True), sys.exit(0)))
count = missed = 0
expected = None
from miro_gen.transport.events.frames import BATCH as H, EVENT as E
while True:
    topic, body = s.recv_multipart()
    n = H.unpack_from(body)[2]
    at = H.size
    for _ in range(n):
        seq, _, _, size = E.unpack_from(body, at)
        at += E.size + size
        if expected is not None and seq > expected:
            missed += seq - expected
        expected = seq + 1
    count += n
"""


def cpu_seconds(proc: subprocess.Popen[str]) -> float:
    """Wait for `proc` and return the CPU time (user + system) it used."""
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return usage.ru_utime + usage.ru_stime


def supply(naming: str, rate: float, seconds: float) -> tuple[int, float]:
    out = subprocess.run(
        [sys.executable, "-c", SUPPLIER, naming, str(rate), str(seconds)],
        capture_output=True,
        text=True,
        env=ENV,
        timeout=seconds + 60,
        check=True,
    ).stdout.split()
    return int(out[0]), float(out[1])


def consumer_endpoint(naming: str) -> str:
    from miro_gen.service.server import Client

    client = Client(["bench", "--naming", naming])
    try:
        return bytes(client.naming.resolve("EventChannel").key).decode()
    finally:
        client.close()


def run_raw(naming: str, rate: float, seconds: float) -> tuple[int, int, int, float, float]:
    counter = subprocess.Popen(
        [sys.executable, "-c", RAW_COUNTER, consumer_endpoint(naming)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert counter.stdout is not None
    counter.stdout.readline()
    sent, elapsed = supply(naming, rate, seconds)
    counter.send_signal(signal.SIGINT)
    line = counter.stdout.readline().split()
    cpu = cpu_seconds(counter)
    return sent, int(line[0]), int(line[1]), elapsed, cpu


def run_recorder(naming: str, rate: float, seconds: float) -> tuple[int, int, int, float, float]:
    from mcap.reader import make_reader

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        rec = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "miro_gen.cli.main",
                "log",
                "record",
                "--naming",
                naming,
                "-o",
                str(path),
            ],
            stderr=subprocess.PIPE,
            text=True,
            env=ENV,
        )
        assert rec.stderr is not None
        rec.stderr.readline()  # "recording ..."
        sent, elapsed = supply(naming, rate, seconds)
        rec.send_signal(signal.SIGINT)
        cpu = cpu_seconds(rec)
        with open(path, "rb") as f:
            seqs = [m.sequence for _, _, m in make_reader(f).iter_messages()]
        missed = sum(b - a - 1 for a, b in itertools.pairwise(seqs) if b > a + 1)
        return sent, len(seqs), missed, elapsed, cpu


def replay_spacing(naming: str) -> tuple[float, float]:
    """Median and 95th percentile (ms) of how far arrivals stray from the recorded spacing."""
    import Miro

    from miro_gen.eventlog.writer import LogWriter
    from miro_gen.transport.events.frames import RawEvent

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "spacing.mcap"
        writer = LogWriter(str(path))
        t = 1_577_836_800_000_000_000
        logged = []
        for n in range(60):
            t += (10, 30, 5)[n % 3] * 1_000_000
            data = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL()).serialize()
            h = Miro.ExampleEventIDL._type_hash
            writer.write([RawEvent("robot1", "ExampleEvent", h, 1, n, t, t, data)], t)
            logged.append(t)
        writer.finish()
        printer = subprocess.Popen(
            [sys.executable, str(PRINTER), "--naming", naming, "-MNC", "gui", "EventChannel"],
            stdout=subprocess.PIPE,
            text=True,
            env=ENV,
        )
        assert printer.stdout is not None
        printer.stdout.readline()  # READY
        subprocess.run(
            [*MIRO, "log", "play", str(path), "--naming", naming, "-MNC", "robot1"],
            capture_output=True,
            env=ENV,
            timeout=60,
            check=True,
        )
        printer.send_signal(signal.SIGTERM)
        out, _ = printer.communicate(timeout=20)
    received = [json.loads(line)["received"] for line in out.splitlines() if line[:1] == "{"]
    offsets = [r - t for r, t in zip(received, logged, strict=True)][2:]
    middle = statistics.median(offsets)
    deviations = sorted(abs(o - middle) / 1e6 for o in offsets)
    return statistics.median(deviations), deviations[int(0.95 * (len(deviations) - 1))]


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--rate", type=float, default=TARGET, help="events per second")
    ap.add_argument("--seconds", type=float, default=5.0, help="how long the supplier pushes")
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    port = free_port()
    naming_endpoint = f"tcp://127.0.0.1:{port}"
    naming = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "miro_gen.cli.main",
            "naming",
            "--endpoint",
            naming_endpoint,
            "--channel",
            "EventChannel",
        ],
        stdout=subprocess.PIPE,
        text=True,
        env=ENV,
    )
    assert naming.stdout is not None
    naming.stdout.readline()
    rows = {}
    try:
        rows["raw pyzmq SUB, counting only"] = run_raw(naming_endpoint, args.rate, args.seconds)
        rows["miro log record (MCAP, zstd)"] = run_recorder(
            naming_endpoint, args.rate, args.seconds
        )
        spacing = [replay_spacing(naming_endpoint) for _ in range(3)]
    finally:
        naming.kill()
        naming.wait()
    print(f"supplier: {args.rate:.0f} events/s for {args.seconds:g} s, 28-byte payloads")
    print(f"{'receiver':32} {'sent':>8} {'received':>9} {'lost':>6} {'events/s':>9} {'CPU s':>6}")
    lost_by_recorder = 0
    for name, (sent, got, missed, elapsed, cpu) in rows.items():
        lost = sent - got
        print(f"{name:32} {sent:8d} {got:9d} {lost:6d} {got / elapsed:9.0f} {cpu:6.2f}")
        if name.startswith("miro"):
            lost_by_recorder = lost + missed
    verdict = "ok" if lost_by_recorder == 0 else "MISSED"
    print(f"recorder at {args.rate:.0f} events/s: {lost_by_recorder} lost ({verdict})")
    figures = ", ".join(f"{median:.2f} / {p95:.2f}" for median, p95 in spacing)
    print(f"replay at 1x, arrivals off the recorded spacing, median / 95th pct ms: {figures}")
    return 1 if args.check and lost_by_recorder else 0


if __name__ == "__main__":
    sys.exit(main())
