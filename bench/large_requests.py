"""Benchmark: large request bodies from a caller on the server's host (issue 29), through the
caller's shared memory (transport.rpc.shared) against the same call in frames and a raw pyzmq
DEALER/ROUTER round trip carrying the same bytes.

    python bench/large_requests.py [--sizes 65536,1048576,8000000] [--runs 5] [--seconds 2]

The server (tests/procs/body_server.py, operation `size`) answers each request with its body's
length only; the raw server receives the frames without a copy (copy=False) and answers as
small a reply. Each size is measured for at least `seconds` per run in interleaved blocks,
`runs` times; the ratio printed is the median of the runs' p50 ratios to the raw row, with
their spread, and the load average.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import zmq

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

from large_replies import print_rows, run_interleaved  # noqa: E402 - beside this file

from miro_gen.runtime.cdr import ObjectRef  # noqa: E402
from miro_gen.transport.rpc.invoker import ZmqInvoker  # noqa: E402

RAW_SERVER = """
import zmq
ctx = zmq.Context()
s = ctx.socket(zmq.ROUTER)
port = s.bind_to_random_port("tcp://127.0.0.1")
print(port, flush=True)
reply = bytes(24), bytes(12)
while True:
    peer, header, body = s.recv_multipart(copy=False)
    s.send_multipart([peer, *reply])
"""


class Ours:
    """A call of `size` with `body` through the invoker; `shared`: may take shared memory."""

    def __init__(self, endpoint: str, body: bytes, shared: bool) -> None:
        self.invoker = ZmqInvoker(zmq.Context())
        self.ref = ObjectRef("IDL:Test/Body:1.0", endpoint, b"Body")
        self.body = body
        self.call()  # the first reply: the server's routing id says it takes them
        if not shared:
            self.invoker._local.conns[endpoint].takes_requests = False

    def call(self) -> None:
        reply = self.invoker.invoke(self.ref, "size", self.body, timeout=10.0)
        assert reply is not None and reply.status == 0

    def close(self) -> None:
        self.invoker.close()


class Raw:
    def __init__(self, port: str, body: bytes) -> None:
        self.context: zmq.Context[Any] = zmq.Context()
        self.socket = self.context.socket(zmq.DEALER)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.connect(f"tcp://127.0.0.1:{port}")
        self.request = [bytes(32), body]

    def call(self) -> None:
        self.socket.send_multipart(self.request, copy=False)
        self.socket.recv_multipart()

    def close(self) -> None:
        self.socket.close()
        self.context.term()


def _start(args: list[str]) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    return proc, proc.stdout.readline().split()[1 if "body_server" in args[1] else 0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="65536,1048576,8000000")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=2.0)
    args = ap.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'request (median of runs)':30} {'size':>9} {'p50 us':>9} {'ratio':>6} {'runs':>12}")
    procs = ROOT / "tests" / "procs"
    for size in (int(s) for s in args.sizes.split(",")):
        body = random.Random(size).randbytes(size)
        server, endpoint = _start([sys.executable, str(procs / "body_server.py")])
        raw, port = _start([sys.executable, "-c", RAW_SERVER])
        clients: dict[str, Any] = {
            "raw pyzmq (copy=False)": Raw(port, body),
            "ours, in frames": Ours(endpoint, body, False),
            "ours, shared memory": Ours(endpoint, body, True),
        }
        try:
            for client in clients.values():
                for _ in range(20):
                    client.call()
            results = [run_interleaved(clients, args.seconds) for _ in range(args.runs)]
        finally:
            for client in clients.values():
                client.close()
            for proc in (server, raw):
                proc.kill()
                proc.wait()
        pool = clients["ours, shared memory"].invoker.requests
        print(f"{size} B: {pool.shared if pool else 0} of the shared row's bodies in shared memory")
        print_rows(results, "raw pyzmq (copy=False)", size, 30, 12)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
