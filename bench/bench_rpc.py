"""Benchmark: a generated-stub getData() round trip against a raw pyzmq DEALER/ROUTER echo,
and beside them a Zenoh get/reply round trip.

    python bench/bench_rpc.py [--calls N] [--check]

Each server runs in its own process on loopback. The raw echo returns the same bytes our reply
carries (header and CDR body), so the ratio is the cost of everything miro-gen adds: stubs, CDR,
frames, the worker pool. Prints p50 and p99 latency of both and the ratio of the p50s. Target
(issue "The ZeroMQ transport"): at most 1.25x. `--check` exits 1 when it is missed.

If `eclipse-zenoh` is installed (pip install miro-gen[bench]), a Zenoh queryable in a peer of its
own (loopback, multicast scouting off, explicit endpoints) echoes the same bytes to a querier's
get(), for comparison only: the time to the reply's arrival, from a Python caller.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import zmq  # noqa: E402

from miro_gen.runtime.cdr import ObjectRef  # noqa: E402
from miro_gen.transport.invoker import ZmqInvoker  # noqa: E402

TARGET = 1.25

try:
    import zenoh
except ImportError:  # optional: pip install miro-gen[bench]
    zenoh = None

ECHO = """
import sys, zmq
ctx = zmq.Context()
s = ctx.socket(zmq.ROUTER)
port = s.bind_to_random_port("tcp://127.0.0.1")
print(port, flush=True)
while True:
    s.send_multipart(s.recv_multipart())
"""


ZENOH_ECHO = """
import sys, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:' + sys.argv[1] + '"]')
session = zenoh.open(conf)
queryable = session.declare_queryable(
    "bench/getData", lambda q: q.reply(q.key_expr, q.payload.to_bytes())
)
print(sys.argv[1], flush=True)
sys.stdin.read()
"""


def zenoh_port() -> str:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return str(s.getsockname()[1])


def bench_zenoh(port: str, calls: int, frames: list[bytes]) -> list[float]:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{port}"]')
    session = zenoh.open(conf)
    querier = session.declare_querier("bench/getData", timeout=5.0)
    data = b"".join(frames)

    def call() -> None:
        for reply in querier.get(payload=data):
            reply.ok.payload.to_bytes()
            return
        raise RuntimeError("no reply from the Zenoh queryable")

    for _ in range(200):
        call()
    out = []
    for _ in range(calls):
        t = time.perf_counter()
        call()
        out.append(time.perf_counter() - t)
    querier.undeclare()
    session.close()
    return out


def start(args: list[str]) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    return proc, proc.stdout.readline().split()[-1]


def percentiles(samples: list[float]) -> tuple[float, float]:
    samples = sorted(samples)
    return statistics.median(samples), samples[int(len(samples) * 0.99) - 1]


def bench_ours(endpoint: str, calls: int) -> list[float]:
    inv = ZmqInvoker(zmq.Context())
    stub = Miro.Example(ObjectRef("IDL:Miro/Example:1.0", endpoint, b"ExampleA"), inv)
    for _ in range(200):
        stub.getData()
    out = []
    for _ in range(calls):
        t = time.perf_counter()
        stub.getData()
        out.append(time.perf_counter() - t)
    inv.close()
    return out


def bench_raw(port: str, calls: int, frames: list[bytes]) -> list[float]:
    ctx = zmq.Context()
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(f"tcp://127.0.0.1:{port}")
    for _ in range(200):
        s.send_multipart(frames)
        s.recv_multipart()
    out = []
    for _ in range(calls):
        t = time.perf_counter()
        s.send_multipart(frames)
        s.recv_multipart()
        out.append(time.perf_counter() - t)
    s.close()
    ctx.term()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--calls", type=int, default=5000)
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    server, endpoint = start([sys.executable, str(ROOT / "tests/procs/example_server.py")])
    echo, port = start([sys.executable, "-c", ECHO])
    reply = [bytes(24), Miro.ExampleStructIDL(1.0, 11.0).serialize()]
    try:
        raw = bench_raw(port, args.calls, reply)
        ours = bench_ours(endpoint, args.calls)
    finally:
        server.kill()
        echo.kill()
    z = None
    if zenoh is not None:
        queryable = subprocess.Popen(
            [sys.executable, "-c", ZENOH_ECHO, zenoh_port()],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert queryable.stdout is not None
        try:
            z = bench_zenoh(queryable.stdout.readline().strip(), args.calls, reply)
        finally:
            queryable.kill()
            queryable.wait()
    (o50, o99), (r50, r99) = percentiles(ours), percentiles(raw)
    print(f"{'round trip':28} {'p50 us':>8} {'p99 us':>8}")
    print(f"{'miro-gen getData()':28} {o50 * 1e6:8.1f} {o99 * 1e6:8.1f}")
    print(f"{'raw pyzmq DEALER/ROUTER':28} {r50 * 1e6:8.1f} {r99 * 1e6:8.1f}")
    if z is not None:
        z50, z99 = percentiles(z)
        print(f"{'Zenoh get/reply (peer)':28} {z50 * 1e6:8.1f} {z99 * 1e6:8.1f}")
    ratio = o50 / r50
    verdict = "ok" if ratio <= TARGET else "MISSED"
    print(f"p50 ratio miro-gen / raw pyzmq: {ratio:.2f} (target <= {TARGET}: {verdict})")
    if z is not None:
        print(f"p50 ratio miro-gen / Zenoh get: {o50 / percentiles(z)[0]:.2f}")
    else:
        print("zenoh: skipped (eclipse-zenoh not installed)")
    return 1 if args.check and ratio > TARGET else 0


if __name__ == "__main__":
    sys.exit(main())
