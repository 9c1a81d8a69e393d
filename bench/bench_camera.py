"""Benchmark: the camera service delivering 1280x720 images at 30 Hz to a consumer process, against
raw pyzmq carrying the same bytes at the same rate, in the same run.

    python bench/bench_camera.py [--frames N] [--repeat R] [--encoding bgr8|jpeg|...]

miro-gen: `miro sim camera` writes N frames of 1280x720 Motion JPEG at 30 Hz; services/camera
plays the file at Rate 30, converting each frame to the encoding (bgr8: 2.76 MB of raw pixels)
and publishing it as an ImageEventIDL on an event channel it hosts; a consumer process
(`StructuredPushConsumer`) receives them, decodes the payload and counts: images, gaps in the
frame numbers and in the channel's sequence numbers, the rate between its first and last image,
and the latency from capture to the callback (p50, p99).

Baseline: a PUB socket sending the same number of payloads of the same size at 30 Hz through a
zmq.proxy XSUB/XPUB in the supplier's process (as our channel host) to a SUB socket in another
process: what ZeroMQ itself delivers.

Target (issue 20): the configured rate (ratio to 30 Hz near 1.0) with no image lost. The machine
is shared with other work: compare the rows of one run, and look at several repetitions.
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]

import zmq  # noqa: E402

WIDTH, HEIGHT, RATE = 1280, 720, 30.0


def summarise(arrivals: list[float], numbers: list[int], latencies: list[float]) -> dict[str, Any]:
    gaps = sum(b - a - 1 for a, b in itertools.pairwise(numbers) if b > a + 1)
    span = arrivals[-1] - arrivals[0] if len(arrivals) > 1 else 0.0
    lat = sorted(latencies) or [0.0]
    return {
        "received": len(numbers),
        "lost": gaps + (numbers[0] if numbers else 0),
        "rate": (len(arrivals) - 1) / span if span else 0.0,
        "p50_ms": 1e3 * lat[len(lat) // 2],
        "p99_ms": 1e3 * lat[min(len(lat) - 1, int(len(lat) * 0.99))],
    }


# ---- consumer processes ---------------------------------------------------------------------


def miro_consumer(naming: str, expected: int) -> None:
    import Miro  # noqa: F401 - the payload's type, for decoding

    from miro_gen import StructuredEvent, StructuredPushConsumer
    from miro_gen.service.server import Server

    arrivals: list[float] = []
    numbers: list[int] = []
    latencies: list[float] = []
    seqs: list[int] = []
    done = threading.Event()

    class Counter(StructuredPushConsumer):
        def push_structured_event(self, event: StructuredEvent) -> None:
            now = time.time()
            image = event.payload
            arrivals.append(now)
            numbers.append(image.frame)
            seqs.append(event.seq)
            latencies.append(now - (image.time.sec + image.time.usec / 1e6))
            if len(numbers) >= expected:
                done.set()

    server = Server(["consumer", "--naming", naming, "-MNC", "bench"])
    threading.Thread(target=server.run, daemon=True).start()
    while True:
        try:
            channel = server.resolve_channel("rover/EventChannel")
            break
        except Exception:  # the camera has not bound it yet
            time.sleep(0.1)
    counter = Counter(channel)
    counter.set_subscriptions([("rover", "Image")])
    print("READY", flush=True)
    done.wait(float(sys.stdin.readline() or "60"))
    result = summarise(arrivals, numbers, latencies)
    result["missed"] = counter.missed
    print(json.dumps(result), flush=True)
    server.shutdown()


def raw_consumer(endpoint: str, expected: int, timeout: float) -> None:
    ctx = zmq.Context()
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(endpoint)
    print("READY", flush=True)
    arrivals: list[float] = []
    numbers: list[int] = []
    latencies: list[float] = []
    poller = zmq.Poller()
    poller.register(sub, zmq.POLLIN)
    end = time.monotonic() + timeout
    while len(numbers) < expected and time.monotonic() < end:
        if not poller.poll(200):
            continue
        head, data = sub.recv_multipart(copy=False)
        now = time.time()
        number, stamp = json.loads(bytes(head.buffer))
        arrivals.append(now)
        numbers.append(number)
        latencies.append(now - stamp)
        del data
    print(json.dumps(summarise(arrivals, numbers, latencies)), flush=True)


# ---- runs -----------------------------------------------------------------------------------


def run_miro(video: Path, frames: int, encoding: str, tmp: Path) -> dict[str, Any]:
    from device_rig import Driver
    from loopback import NamingProcess, eventually, service_env

    naming = NamingProcess()
    consumer = None
    driver = None
    try:
        config = {"Rate": RATE, "Encoding": encoding, "Width": WIDTH, "Height": HEIGHT}
        missing = tmp / "not-yet.avi"  # the camera waits for it: the consumer subscribes first
        driver = Driver("camera", "Camera", naming.endpoint, tmp / "camera.log",
                        Device=missing, **config)  # fmt: skip
        driver_args = [sys.executable, __file__, "--consume-miro", naming.endpoint, str(frames)]
        consumer = subprocess.Popen(
            driver_args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
            env=service_env(),
        )  # fmt: skip
        assert consumer.stdout is not None and consumer.stdin is not None
        assert consumer.stdout.readline().strip() == "READY"
        eventually(lambda: driver.logged("someone subscribes") == 1, 30)  # type: ignore[union-attr]
        missing.symlink_to(video)
        consumer.stdin.write(f"{frames / RATE * 3 + 30}\n")
        consumer.stdin.flush()
        result: dict[str, Any] = json.loads(consumer.stdout.readline())
        result["service"] = driver.stop().strip().splitlines()[-1]
        return result
    finally:
        if consumer is not None and consumer.poll() is None:
            consumer.kill()
        if driver is not None:
            driver.kill()
        naming.stop()


def run_raw(frames: int, size: int) -> dict[str, Any]:
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
    consumer = subprocess.Popen(
        [sys.executable, __file__, "--consume-raw", f"tcp://127.0.0.1:{port_out}", str(frames),
         str(frames / RATE * 3 + 30)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert consumer.stdout is not None
    assert consumer.stdout.readline().strip() == "READY"
    time.sleep(1.0)  # the subscription reaches the proxy (slow joiner)
    payload = bytes(size)
    start = time.monotonic()
    for n in range(frames):
        time.sleep(max(0.0, start + n / RATE - time.monotonic()))
        pub.send_multipart([json.dumps([n, time.time()]).encode(), payload])
    result: dict[str, Any] = json.loads(consumer.stdout.readline())
    consumer.wait(10)
    return result


def row(name: str, r: dict[str, Any]) -> str:
    return (
        f"{name:22s} {r['received']:5d} received {r['lost']:4d} lost "
        f"{r['rate']:6.2f} Hz ({r['rate'] / RATE:4.2f}x of {RATE:g})  "
        f"latency p50 {r['p50_ms']:6.1f} ms  p99 {r['p99_ms']:6.1f} ms"
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=300, help="frames a run (default 300: 10 s)")
    p.add_argument("--repeat", type=int, default=3, help="runs of each (default 3)")
    p.add_argument("--encoding", default="bgr8", help="the camera's Encoding (default bgr8)")
    p.add_argument("--consume-miro", nargs=2, help=argparse.SUPPRESS)
    p.add_argument("--consume-raw", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.consume_miro:
        miro_consumer(args.consume_miro[0], int(args.consume_miro[1]))
        return 0
    if args.consume_raw:
        raw_consumer(args.consume_raw[0], int(args.consume_raw[1]), float(args.consume_raw[2]))
        return 0
    from miro_gen.sim.camera import write_video

    size = WIDTH * HEIGHT * 3
    print(f"{args.frames} frames of {WIDTH}x{HEIGHT} at {RATE:g} Hz, encoding {args.encoding}")
    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "video.avi"
        write_video(video, args.frames, WIDTH, HEIGHT, RATE)
        rates = []
        for n in range(args.repeat):
            run_dir = Path(tmp) / f"run{n}"
            run_dir.mkdir()
            ours = run_miro(video, args.frames, args.encoding, run_dir)
            raw = run_raw(args.frames, size)
            print(row("miro-gen camera", ours))
            print(f"{'':22s} {ours['service']}  (consumer missed {ours['missed']})")
            print(row("raw pyzmq, same bytes", raw))
            rates.append(ours["rate"] / raw["rate"] if raw["rate"] else 0.0)
        print(f"miro-gen / raw pyzmq delivered rate: {statistics.median(rates):.2f} (median)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
