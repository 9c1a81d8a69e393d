"""Large events for bench/bench_events.py: camera-sized payloads through an event channel to
consumer processes, against raw pyzmq and Zenoh with the same sizes, and a recorded camera and
laser stream played back by `miro log play`.

1. Throughput: a supplier process pushes N events of 1 MB and of 6 MB (Miro::ImageEventIDL,
   encoded at each push) as fast as it can into a channel it hosts, as a camera service does;
   one consumer process decodes them; the figure is the consumer's frames/s from its first to
   its last frame, and what it lost. Raw pyzmq: PUB -> XSUB/XPUB proxy in the supplier's process
   (tcp, as bench_events' small events) -> SUB, with pyzmq's defaults (copy=True) and with
   copy=False on both sides; the better of the two is the baseline. Zenoh: a publisher
   (congestion control BLOCK) and a subscriber, peers on loopback.
   Target (issue "sensor-rate data"): miro-gen at least 0.8x raw pyzmq's frames/s (aim 1.0x).
2. A camera's rate: 6 MB events at 30 Hz for 5 s to 4 consumer processes: no loss.
3. `miro log play` of a recorded stream (1280x720 RGB images at 30 Hz and 1,081-beam scans at
   40 Hz, 5 s): the rate at which each stream arrives at a consumer process, against the
   recorded rate, and how long the playback takes against the log's length.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import zmq  # noqa: E402
from raw_peers import free_port, zenoh_config  # noqa: E402 - beside this file

SIZES = (1 << 20, 6 << 20)
TOPIC = b"bench\0Image\0"
TARGET = 2.0  # issue 29: shared memory at least twice raw pyzmq
HWM = 64  # frames the raw baseline queues per socket, as miro-gen (sockets.queue_limit)

try:
    import zenoh
except ImportError:  # optional: pip install miro-gen[bench]
    zenoh = None


def image(size: int, n: int = 0) -> Miro.ImageEventIDL:
    width = 1024
    form = Miro.ImageFormatIDL(width, size // (3 * width), Miro.IMAGE_RGB8, 3 * width)
    return Miro.ImageEventIDL(Miro.TimeIDL(n, 0), n, form, bytes([n % 256]) * size)


# ---- processes: commands on stdin, answers on stdout -----------------------------------------


def _lines(handle: Callable[[list[str]], str | None]) -> None:
    for line in sys.stdin:
        answer = handle(line.split())
        if answer is None:
            return
        print(answer, flush=True)


def _run_supplier(send: Callable[[int, int], object], dropped: Callable[[], int]) -> None:
    """RUN count size rate: send `count` events of `size` bytes (rate 0: flat out)."""

    def handle(words: list[str]) -> str | None:
        if words[0] != "RUN":
            return None
        count, size, rate = int(words[1]), int(words[2]), float(words[3])
        start = time.monotonic()
        for i in range(count):
            if rate:
                time.sleep(max(0.0, start + i / rate - time.monotonic()))
            send(i, size)
        return f"SENT {count} {dropped()}"

    _lines(handle)


class Tally:
    """A consumer's count of frames and of the time between the first and the last."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        self.received, self.first, self.last, self.bytes = 0, 0.0, 0.0, 0

    def hit(self, size: int) -> None:
        now = time.monotonic()
        with self.lock:
            if not self.received:
                self.first = now
            self.received += 1
            self.last = now
            self.bytes += size

    def report(self, name: str, missed: int) -> str:
        """`name received missed seconds bytes` since the last report."""
        with self.lock:
            line = f"{name} {self.received} {missed} {self.last - self.first} {self.bytes}"
            self.reset()
        return line


def _run_consumer(tallies: dict[str, Tally], missed: Callable[[], int]) -> None:
    """REPORT: `GOT` and what arrived of each type since the last report, `|` between them."""
    print("READY", flush=True)
    before = [0]  # the consumer's count of missed events at the last report

    def report(words: list[str]) -> str | None:
        if words[0] == "COUNT":  # how many so far, without a report
            return f"COUNT {sum(t.received for t in tallies.values())}"
        if words[0] != "REPORT":
            return None
        now = missed()  # (a running total: each report says what this run missed)
        since, before[0] = now - before[0], now
        return "GOT " + " | ".join(t.report(name, since) for name, t in tallies.items())

    _lines(report)


def got(answer: str) -> dict[str, tuple[int, int, float]]:
    """(received, missed, seconds between the first and the last) by type, of a report."""
    out = {}
    for part in answer.split(" | "):
        name, received, missed, seconds, _ = part.split()
        out[name] = (int(received), int(missed), float(seconds))
    return out


def raw_supplier(copy: str) -> None:
    ctx = zmq.Context()
    xsub, xpub = ctx.socket(zmq.XSUB), ctx.socket(zmq.XPUB)
    for s in (xsub, xpub):
        s.setsockopt(zmq.SNDHWM, HWM)
        s.setsockopt(zmq.RCVHWM, HWM)
    port_in = xsub.bind_to_random_port("tcp://127.0.0.1")
    port_out = xpub.bind_to_random_port("tcp://127.0.0.1")
    threading.Thread(target=zmq.proxy, args=(xsub, xpub), daemon=True).start()
    pub = ctx.socket(zmq.PUB)
    pub.setsockopt(zmq.SNDHWM, HWM)
    pub.connect(f"tcp://127.0.0.1:{port_in}")
    payloads = {size: image(size).serialize() for size in SIZES}
    print("READY", f"tcp://127.0.0.1:{port_out}", flush=True)
    _run_supplier(
        lambda i, size: pub.send_multipart([TOPIC, payloads[size]], copy=copy == "1"), lambda: 0
    )


def raw_consumer(where: str, copy: str) -> None:
    ctx = zmq.Context()
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.RCVHWM, HWM)
    sub.setsockopt(zmq.SUBSCRIBE, TOPIC)
    sub.connect(where)
    tally = Tally()

    def loop() -> None:
        while True:
            parts = sub.recv_multipart(copy=copy == "1")
            tally.hit(len(parts[1]))

    threading.Thread(target=loop, daemon=True).start()
    _run_consumer({"Image": tally}, lambda: 0)


def ours_supplier(naming: str) -> None:
    from miro_gen import EventChannelFactory, Server, StructuredPushSupplier

    server = Server(["bench", "--naming", naming, "-MNC", "bench"])
    channel = EventChannelFactory(server).create_channel("Large")
    supplier = StructuredPushSupplier(channel)
    threading.Thread(target=server.run, daemon=True).start()
    values = {size: image(size) for size in SIZES}
    print("READY", channel.name, flush=True)

    def send(i: int, size: int) -> None:
        value = values[size]
        value.frame = i
        supplier.push("Image", value)

    _run_supplier(send, lambda: supplier.dropped)
    server.shutdown()


def ours_consumer(naming: str, channel: str, types: str = "Image", views: str = "bytes") -> None:
    from miro_gen import Server, StructuredEvent, StructuredPushConsumer
    from miro_gen.transport.events import KEEP_ALL

    # One name per reader process (several run at once): their service objects are bound apart.
    server = Server([f"bench-{os.getpid()}", "--naming", naming, "-MNC", "consumer"])
    tallies = {t: Tally() for t in types.split(",")}

    class Consumer(StructuredPushConsumer):
        def push_structured_event(self, event: StructuredEvent) -> None:
            tallies[event.type_name].hit(0)

    # every event, as the raw baselines deliver every frame (the default keeps the newest 10)
    consumer = Consumer(
        server.resolve_channel(channel), depth=KEEP_ALL, zero_copy=views == "zero-copy"
    )
    consumer.set_subscriptions([("*", t) for t in tallies])
    threading.Thread(target=server.run, daemon=True).start()
    _run_consumer(tallies, lambda: consumer.missed)
    server.shutdown()


def _zenoh_config(listen: str | None, connect: str | None, shm: str) -> Any:
    conf = zenoh_config(listen, connect)
    conf.insert_json5("transport/shared_memory/enabled", "true" if shm == "on" else "false")
    return conf


def zenoh_supplier(port: str, shm: str) -> None:
    session = zenoh.open(_zenoh_config(f"tcp/127.0.0.1:{port}", None, shm))
    pub = session.declare_publisher("bench/Image", congestion_control=zenoh.CongestionControl.BLOCK)
    payloads = {size: image(size).serialize() for size in SIZES}
    print("READY", port, flush=True)
    _run_supplier(lambda i, size: pub.put(payloads[size]), lambda: 0)
    session.close()


def zenoh_consumer(port: str, shm: str) -> None:
    session = zenoh.open(_zenoh_config(None, f"tcp/127.0.0.1:{port}", shm))
    tally = Tally()
    sub = session.declare_subscriber("bench/Image", lambda s: tally.hit(len(s.payload)))
    _run_consumer({"Image": tally}, lambda: 0)
    sub.undeclare()
    session.close()


ROLES: dict[str, Callable[..., None]] = {
    "large-raw-supplier": raw_supplier,
    "large-raw-consumer": raw_consumer,
    "large-ours-supplier": ours_supplier,
    "large-ours-consumer": ours_consumer,
    "large-zenoh-supplier": zenoh_supplier,
    "large-zenoh-consumer": zenoh_consumer,
}


class Process:
    def __init__(self, role: str, *args: str, env: dict[str, str] | None = None) -> None:
        self.proc = subprocess.Popen(
            [
                sys.executable,
                str(Path(__file__).with_name("bench_events.py")),
                "--role",
                role,
                *args,
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=dict(os.environ, **(env or {})),
        )
        self.said = self.expect("READY")

    def expect(self, word: str) -> str:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith(word):
            raise RuntimeError(f"{self.proc.args[3]} said {line!r}, expected {word}")
        return line[len(word) :].strip()

    def ask(self, *words: object, answer: str) -> str:
        assert self.proc.stdin is not None
        self.proc.stdin.write(" ".join(map(str, words)) + "\n")
        self.proc.stdin.flush()
        return self.expect(answer)

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def frames_per_second(
    supplier: Process, consumers: list[Process], count: int, size: int, rate: float = 0
) -> list[tuple[float, int]]:
    """(frames/s, lost) at each consumer for one run."""
    supplier.ask("RUN", count, size, rate, answer="SENT")
    for c in consumers:  # until each has all, or nothing more for a second
        seen, since = -1, time.monotonic()
        while time.monotonic() - since < 1.0:
            now = int(c.ask("COUNT", answer="COUNT"))
            if now >= count:
                break
            if now != seen:
                seen, since = now, time.monotonic()
            time.sleep(0.05)
    out = []
    for c in consumers:
        received, missed, seconds = got(c.ask("REPORT", answer="GOT"))["Image"]
        fps = (received - 1) / seconds if received > 1 and seconds > 0 else 0.0
        out.append((fps, max(missed, count - received)))
    return out


def naming_service(*options: str) -> tuple[subprocess.Popen[str], str]:
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint", endpoint, *options],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    proc.stdout.readline()
    return proc, endpoint


class Setup:
    """One transport with its supplier and `consumers` consumer processes, kept for all runs."""

    def __init__(self, name: str, consumers: int) -> None:
        self.name = name
        self.stop: Callable[[], object] = lambda: None
        if name.startswith("raw"):
            copy = "1" if "copy=True" in name else "0"
            self.supplier = Process("large-raw-supplier", copy)
            self.consumers = [
                Process("large-raw-consumer", self.supplier.said, copy) for _ in range(consumers)
            ]
        elif name.startswith("miro-gen"):
            env = {"MIRO_SHM": "1" if "shared memory" in name else "0"}
            naming, endpoint = naming_service()
            self.stop = naming.kill
            self.supplier = Process("large-ours-supplier", endpoint, env=env)
            views = "zero-copy" if "zero_copy" in name else "bytes"
            self.consumers = [
                Process(
                    "large-ours-consumer", endpoint, self.supplier.said, "Image", views, env=env
                )
                for _ in range(consumers)
            ]
        else:
            shm = "on" if "on)" in name else "off"
            port = str(free_port())
            self.supplier = Process("large-zenoh-supplier", port, shm)
            self.consumers = [Process("large-zenoh-consumer", port, shm) for _ in range(consumers)]
        time.sleep(1.0)
        frames_per_second(self.supplier, self.consumers, 20, SIZES[0], 100)  # connect, warm up

    def run(self, count: int, size: int) -> tuple[float, int]:
        """(frames/s, lost) of one flat-out run: the mean rate over the consumers, all lost."""
        runs = frames_per_second(self.supplier, self.consumers, count, size)
        return statistics.mean(r[0] for r in runs), sum(r[1] for r in runs)

    def close(self) -> None:
        self.supplier.close()
        for c in self.consumers:
            c.close()
        self.stop()


RAW = ("raw pyzmq (copy=True)", "raw pyzmq (copy=False)")
OURS = "miro-gen, shared memory"
SETUPS = (*RAW, OURS, "miro-gen, shared memory, zero_copy", "miro-gen, ZeroMQ (MIRO_SHM=0)")
ZENOH = ("Zenoh pub/sub (peer, shm off)", "Zenoh pub/sub (peer, shm on)")


def throughput(
    count: int, repeat: int, readers: tuple[int, ...] = (1, 4), seconds: float = 2.0
) -> dict[tuple[str, int, int], list[float]]:
    """frames/s of every run by (transport, consumers, size): `repeat` rounds, each running
    every transport once (interleaved, so that the machine's load falls on all alike); each run
    about `seconds` s (its count from a first run: at least 1,000 events where the transport
    manages 500/s). Prints the medians, spread (min-max) and what was lost, with the load
    average of each round."""
    names = [*SETUPS, *(ZENOH if zenoh is not None else ())]
    results: dict[tuple[str, int, int], list[float]] = {}
    lost: dict[tuple[str, int, int], int] = {}
    loads = []
    for n in readers:
        setups = [Setup(name, n) for name in names]
        try:
            counts = {}
            for setup in setups:  # how many events make `seconds` of work
                for size in SIZES:
                    fps, _ = setup.run(60, size)
                    counts[setup.name, size] = max(60, int(fps * seconds))
            for _ in range(repeat):
                loads.append(os.getloadavg()[0])
                for size in SIZES:
                    for setup in setups:
                        fps, missed = setup.run(counts[setup.name, size], size)
                        key = (setup.name, n, size)
                        results.setdefault(key, []).append(fps)
                        lost[key] = lost.get(key, 0) + missed
                        print(
                            f"  {setup.name}, {n} reader(s), {size >> 20} MiB: {fps:.1f}/s,"
                            f" lost {missed}",
                            flush=True,
                        )
        finally:
            for setup in setups:
                setup.close()
    head = (
        f"{'large events':34} {'readers':>7} {'size':>5} {'frames/s':>9} {'spread':>17} {'lost':>6}"
    )
    print(head)
    for (name, n, size), runs in results.items():
        spread = f"{min(runs):.0f}-{max(runs):.0f}"
        median = statistics.median(runs)
        print(f"{name:34} {n:7} {size >> 20:4}M {median:9.1f} {spread:>17} {lost[name, n, size]:6}")
    print(
        f"{repeat} interleaved rounds per row, each run about {seconds:g} s; "
        f"load average (1 min) at each round: {', '.join(f'{x:.2f}' for x in loads)}"
    )
    return results


def camera_rate(seconds: float = 5.0, consumers: int = 4, hz: float = 30.0) -> bool:
    """6 MB events at `hz` to `consumers` processes: whether none was lost."""
    naming, endpoint = naming_service()
    supplier = Process("large-ours-supplier", endpoint)
    readers = [Process("large-ours-consumer", endpoint, supplier.said) for _ in range(consumers)]
    try:
        time.sleep(1.0)
        frames_per_second(supplier, readers, 10, SIZES[1], hz)  # connect
        count = int(seconds * hz)
        runs = frames_per_second(supplier, readers, count, SIZES[1], hz)
    finally:
        supplier.close()
        for r in readers:
            r.close()
        naming.kill()
    lost = sum(r[1] for r in runs)
    rates = ", ".join(f"{r[0]:.1f}" for r in runs)
    verdict = "ok" if not lost else "MISSED"
    print(
        f"6 MB at {hz:g} Hz for {seconds:g} s to {consumers} consumer processes: frames/s {rates}, "
        f"lost {lost} (target: none: {verdict})"
    )
    return not lost


def sensor_log(path: Path, seconds: float) -> tuple[int, int]:
    """A log of 1280x720 RGB images at 30 Hz and 1,081-beam scans at 40 Hz: (images, scans)."""
    from miro_gen.eventlog.writer import LogWriter
    from miro_gen.sim.laser import LaserScans
    from miro_gen.transport.events.frames import RawEvent

    writer = LogWriter(str(path))
    t0 = 1_577_836_800_000_000_000
    scans = LaserScans()
    events = []
    for n in range(int(seconds * 30)):
        form = Miro.ImageFormatIDL(1280, 720, Miro.IMAGE_RGB8, 3840)
        value = Miro.ImageEventIDL(Miro.TimeIDL(n, 0), n, form, bytes([n % 256]) * (3840 * 720))
        events.append((t0 + n * 1_000_000_000 // 30, "Camera", value, n))
    for n in range(int(seconds * 40)):
        value = Miro.RangeScanEventIDL(Miro.TimeIDL(n, 0), [scans.scan(n)])
        events.append((t0 + n * 25_000_000, "Laser", value, n))
    for t, kind, value, n in sorted(events, key=lambda e: e[0]):
        raw = RawEvent(
            "rover",
            kind,
            value._type_hash,
            1 if kind == "Camera" else 2,
            n,
            t,
            t,
            value.serialize(),
        )
        writer.write([raw], t)
    writer.finish()
    return int(seconds * 30), int(seconds * 40)


def log_play_rate(seconds: float = 5.0) -> bool:
    """Play a recorded camera and laser stream: each stream's rate at a consumer process."""
    naming, endpoint = naming_service("--channel", "EventChannel")
    wait = 1.5
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "sensors.mcap"
        images, scans = sensor_log(log, seconds)
        reader = Process("large-ours-consumer", endpoint, "EventChannel", "Camera,Laser")
        try:
            start = time.monotonic()
            play = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "miro_gen.cli.main",
                    "log",
                    "play",
                    str(log),
                    "--naming",
                    endpoint,
                    "--wait",
                    str(wait),
                ],
                capture_output=True,
                text=True,
                timeout=seconds * 10 + 30,
            )
            took = time.monotonic() - start - wait
            time.sleep(1.0)
            report = got(reader.ask("REPORT", answer="GOT"))
        finally:
            reader.close()
            naming.kill()
    if play.returncode:
        print(f"miro log play failed: {play.stderr}")
        return False
    (cam, cam_missed, cam_s), (las, las_missed, las_s) = report["Camera"], report["Laser"]
    ok = (cam, las, cam_missed, las_missed) == (images, scans, 0, 0)
    cam_hz = (cam - 1) / cam_s if cam_s else 0.0
    laser_hz = (las - 1) / las_s if las_s else 0.0
    print(
        f"miro log play, {seconds:g} s of 1280x720 RGB at 30 Hz and 1,081-beam scans at 40 Hz "
        f"to a consumer process: images {cam}/{images} at {cam_hz:.1f} Hz, scans {las}/{scans} "
        f"at {laser_hz:.1f} Hz, in {took:.2f} s (process start-up included); "
        f"{'all delivered' if ok else 'LOST some'}"
    )
    return ok


def main(count: int, repeat: int) -> bool:
    results = throughput(count, repeat)
    ok = True
    for n in (1, 4):
        for size in SIZES:
            raw = max(statistics.median(results[name, n, size]) for name in RAW)
            ours = statistics.median(results[OURS, n, size])
            ratio = ours / raw if raw else 0.0
            ok &= ratio >= TARGET
            verdict = "ok" if ratio >= TARGET else "MISSED"
            print(
                f"{size >> 20} MiB events to {n} consumer process(es): miro-gen (shared memory) / "
                f"raw pyzmq (better of the two) {ratio:.2f} (target >= {TARGET}: {verdict})"
            )
    if zenoh is None:
        print("zenoh: skipped (eclipse-zenoh not installed)")
    ok &= camera_rate()
    ok &= log_play_rate()
    return ok
