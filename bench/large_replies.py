"""The large-reply rows of bench_rpc.py (`--sizes`): Camera::getImage() returning an image of
each size through a generated stub, against a raw pyzmq DEALER/ROUTER server that answers a
small request with the same two frames our server sends (header and CDR body), received as
`bytes` (recv_multipart, one copy) and, beside it, as frames (copy=False, no copy).

Each size is measured for at least `seconds` per run in interleaved blocks, `runs` times; the
ratio printed is the median of the runs' p50 ratios, with their spread, and the load average.
Our replies of 64 KiB and more come through the server's shared memory (transport.rpc.shared)
unless MIRO_SHM=0; each size's line says how many did.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import zmq

ROOT = Path(__file__).resolve().parents[1]

RAW_SERVER = """
import sys, zmq
sys.path[:0] = [sys.argv[2]]
from camera_server import Camera
reply = [bytes(24), Camera(int(sys.argv[1])).image.serialize()]  # the body our server sends
ctx = zmq.Context()
s = ctx.socket(zmq.ROUTER)
port = s.bind_to_random_port("tcp://127.0.0.1")
print(port, flush=True)
while True:
    peer, _, _ = s.recv_multipart()
    s.send_multipart([peer, *reply], copy=False)
"""


RAW_ROWS = ("raw pyzmq (bytes)", "raw pyzmq (frames, copy=False)")


def shm_env() -> str:
    return os.environ.get("MIRO_SHM", "1 (default)")


def _start(args: list[str]) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    return proc, proc.stdout.readline().split()[-1]


class Ours:
    def __init__(self, endpoint: str) -> None:
        import Miro

        from miro_gen.runtime.cdr import ObjectRef
        from miro_gen.transport.rpc.invoker import ZmqInvoker

        self.invoker = ZmqInvoker(zmq.Context())
        self.stub = Miro.Camera(ObjectRef("IDL:Miro/Camera:1.0", endpoint, b"Camera"), self.invoker)

    def call(self) -> None:
        self.stub.getImage()

    def body(self) -> bytes:
        return self.stub.getImage().serialize()  # the bytes of the reply's body

    def close(self) -> None:
        self.invoker.close()


class Raw:
    def __init__(self, port: str, copy: bool) -> None:
        self.context = zmq.Context()
        self.socket = self.context.socket(zmq.DEALER)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.connect(f"tcp://127.0.0.1:{port}")
        self.request = [bytes(24), bytes(16)]  # about what our request header and body are
        self.copy = copy

    def call(self) -> None:
        self.socket.send_multipart(self.request)
        self.socket.recv_multipart(copy=self.copy)

    def body(self) -> bytes:
        self.socket.send_multipart(self.request)
        return bytes(self.socket.recv_multipart()[1])

    def close(self) -> None:
        self.socket.close()
        self.context.term()


def run_interleaved(clients: dict[str, Any], seconds: float) -> dict[str, list[float]]:
    """One run: interleaved blocks of calls per client until `seconds` have passed."""
    samples: dict[str, list[float]] = {name: [] for name in clients}
    clock = time.perf_counter
    t = clock()
    for client in clients.values():
        client.call()
    block = max(5, int(0.05 / max((clock() - t) / len(clients), 1e-6)))
    start = clock()
    while clock() - start < seconds:
        for name, client in clients.items():
            out, call = samples[name], client.call
            for _ in range(block):
                t = clock()
                call()
                out.append(clock() - t)
    return samples


def print_rows(
    results: list[dict[str, list[float]]], base: str, size: int, name_width: int, spread_width: int
) -> None:
    """One line per client: the median of its runs' p50 (us), and of their ratios to `base`'s
    p50 of the same run, with the ratios' spread."""
    for name in results[0]:
        p50s = [statistics.median(r[name]) for r in results]
        ratios = [statistics.median(r[name]) / statistics.median(r[base]) for r in results]
        spread = f"{min(ratios):.2f}-{max(ratios):.2f}"
        print(
            f"{name:{name_width}} {size:9d} {statistics.median(p50s) * 1e6:9.1f} "
            f"{statistics.median(ratios):6.2f} {spread:>{spread_width}}"
        )


def measure(sizes: list[int], runs: int, seconds: float) -> None:
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'reply (median of runs)':34} {'size':>9} {'p50 us':>9} {'ratio':>6} {'runs':>22}")
    for size in sizes:
        procs = ROOT / "tests" / "procs"
        server, endpoint = _start([sys.executable, str(procs / "camera_server.py"), str(size)])
        raw, port = _start([sys.executable, "-c", RAW_SERVER, str(size), str(procs)])
        clients: dict[str, Any] = {
            "raw pyzmq (bytes)": Raw(port, True),
            "raw pyzmq (frames, copy=False)": Raw(port, False),
            "getImage() stub": Ours(endpoint),
        }
        try:
            # the same bytes from both servers; then warm up
            assert len({client.body() for client in clients.values()}) == 1
            for client in clients.values():
                for _ in range(20):
                    client.call()
            results = [run_interleaved(clients, seconds) for _ in range(runs)]
        finally:
            for client in clients.values():
                client.close()
            for proc in (server, raw):
                proc.kill()
                proc.wait()
        ours = clients["getImage() stub"]
        shared = ours.invoker.shared.read
        print(f"{size} B: {shared} of our replies through shared memory (MIRO_SHM={shm_env()})")
        print_rows(results, "raw pyzmq (bytes)", size, 34, 22)
        better = [  # the target's ratio: ours to the faster raw row of the same run
            statistics.median(r["getImage() stub"])
            / min(statistics.median(r[raw_row]) for raw_row in RAW_ROWS)
            for r in results
        ]
        print(
            f"{'stub / better raw (target 1.1)':34} {size:9d} {'':9} "
            f"{statistics.median(better):6.2f} {f'{min(better):.2f}-{max(better):.2f}':>22}"
        )
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
