"""Benchmark: does `miro log record` keep up with 20,000 small events per second?

    python bench/bench_record.py [--rate 20000] [--seconds 5] [--check]

A naming service hosts the channel; a supplier process pushes ExampleEvents (28-byte CDR
payloads) paced at --rate for --seconds. Two rows, each with the same supplier run: a raw pyzmq
SUB that only counts the events in each frame (the baseline: what the channel delivers), and
`miro log record` writing the MCAP file, whose events are then counted in the file with the
mcap reader and checked for sequence gaps. Both print events received, lost, the rate achieved
and the CPU time the receiving process used. Target (issue 7): the recorder loses nothing at
20,000 events/s; `--check` exits 1 when it does.
"""

from __future__ import annotations

import argparse
import itertools
import os
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "generated"), str(ROOT)]))
TARGET = 20_000

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
from miro_gen.transport.event_frames import BATCH as H, EVENT as E
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


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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
    from miro_gen.transport.server import Client

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
    return 1 if args.check and lost_by_recorder else 0


if __name__ == "__main__":
    sys.exit(main())
