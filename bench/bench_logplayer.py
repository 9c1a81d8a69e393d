"""Benchmark: the log player on a 1 GiB log of 1,000,000 events (issue 28).

    python bench/bench_logplayer.py [--events 1000000] [--file PATH] [--repeats 5]

Writes a log of 1,000,000 Miro::ImageEventIDL events (32x32 random pixels, so that zstd cannot
shrink it: about 1.07 GB), 1,000 a second from robot1 and robot2 in turn, into /tmp (its free
space checked first; deleted at the end unless --file names one to keep or reuse). Then, each
against its baseline in the same run, five interleaved repeats, medians with their spread:

1. Open: the player's model (`FileSet.add`) and `miro log info` (its main, output discarded)
   against the `mcap` library reading the file's summary (`SeekingReader.get_summary`), all
   three in this process (imports done: the work of opening alone); and `miro log info` as a
   command, a process of its own, against a process that imports the `mcap` library and reads
   the summary (start-up included on both sides: what a user waits for). Each repeated for at
   least 2 s a run, each against its own kind of baseline. Target: at most 1.5x (no scan of
   the data).
2. Seek: a seek to a random time while playing at 1x, until a consumer process receives the
   first event at or after it (end to end: model, channel, consumer); beside it the model's
   own read of that event and the `mcap` library's first message from `start_time` (both
   in-process). Target: every seek's first event within 100 ms.
3. Replay timing: `miro log play` of 4 s of the log (4,000 events) at 1x into a bare SUB
   process on the channel (the player's own timing) and into a StructuredPushConsumer process
   (a consumer as services have them), against a bare pyzmq publisher replaying the same
   events on a `time.sleep` loop to a bare SUB: how far each arrival strays from its recorded
   offset (arrival minus log time, against the median of that), p99. Target: within 2 ms.
   Beside it the same bare publisher through an XSUB/XPUB proxy thread of its process (what
   a channel that the player hosts adds to that path).
   With `--before DIR` (a copy of the code before a change), that tree's player too, its runs
   interleaved with this tree's in each repeat.
4. Memory: the resident memory of `miro log play` (the runs above, and 300 s of the log at
   x32) and of the window (`miro log player`, offscreen) while playing the file, sampled every
   50 ms; beside it a process iterating 4 s of events with the `mcap` library. Target: under
   200 MB.
5. Lossless (`--parts lossless`): 10 s of the log (10,001 events) at x32 into a keep-all
   StructuredPushConsumer process, with `--before` that tree's player too: how many arrive.
   Target: all of them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]


def tree_env(root: Path) -> dict[str, str]:
    """The environment of processes that run the miro_gen of the source tree `root` (with
    `python -P`: not the one of the folder they start in)."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(root / "generated"), str(root)]))


ENV = tree_env(ROOT)
PYTHON = [sys.executable, "-P"]
MIRO = [*PYTHON, "-m", "miro_gen.cli.main"]
T0 = 1_700_000_000_000_000_000
GIB = 1 << 30

CONSUMER = """
import json, signal, sys, time, threading
import Miro
from miro_gen import Server, StructuredPushConsumer
from miro_gen.transport.events import KEEP_ALL
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "robot1"])
got = []
class Keep(StructuredPushConsumer):
    def push_structured_event(self, e):
        got.append((time.time_ns(), e.domain_name, e.seq))
while True:
    try:
        channel = server.resolve_channel("EventChannel")
        break
    except Exception:
        time.sleep(0.05)
Keep(channel, depth=KEEP_ALL).set_subscriptions([("*", "*")])
server.reactor().call_soon(lambda: print("READY", flush=True))
server.run()
for r in got:
    print(json.dumps(r))
"""

RAW_TAP = """
import json, signal, sys, time, zmq
from miro_gen.service.server import Client
from miro_gen.transport.events.frames import parse_batch, split_topic
while True:  # the player binds the channel
    try:
        client = Client(["bench-tap", "--naming", sys.argv[1]])
        entry = client.naming.resolve("robot1/EventChannel")
        break
    except Exception:
        time.sleep(0.05)
ctx = zmq.Context()
s = ctx.socket(zmq.SUB)
s.setsockopt(zmq.SUBSCRIBE, b"")
s.connect(bytes(entry.key).decode())
got = []
stop = []
signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
print("READY", flush=True)
while not stop:
    if s.poll(100):
        head, body = s.recv_multipart()
        t = time.time_ns()
        domain, type_name = split_topic(head)
        got.extend((t, domain, e.seq) for e in parse_batch(domain, type_name, body))
for r in got:
    print(json.dumps(r))
"""

RAW_SUB = """
import json, signal, sys, time, zmq
ctx = zmq.Context()
s = ctx.socket(zmq.SUB)
s.setsockopt(zmq.SUBSCRIBE, b"")
s.connect(sys.argv[1])
got = []
stop = []
signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
print("READY", flush=True)
while not stop:
    if s.poll(100):
        topic, body = s.recv_multipart()
        got.append((time.time_ns(), topic.decode(), int.from_bytes(body[:8], "little")))
for r in got:
    print(json.dumps(r))
"""

RAW_PUB = """
import sys, threading, time, zmq
from mcap.reader import make_reader
path, start, end, endpoint = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
with open(path, "rb") as f:
    events = [(m.log_time, ch.topic.encode(), m.sequence.to_bytes(8, "little") + m.data)
              for _, ch, m in make_reader(f).iter_messages(starting_at=start, ending_before=end)]
ctx = zmq.Context()
s = ctx.socket(zmq.PUB)
if sys.argv[5:] == ["proxy"]:  # through an XSUB/XPUB proxy thread, as a hosted channel's
    xsub, xpub = ctx.socket(zmq.XSUB), ctx.socket(zmq.XPUB)
    xsub.bind("inproc://channel")
    xpub.bind(endpoint)
    threading.Thread(target=zmq.proxy, args=(xsub, xpub), daemon=True).start()
    s.connect("inproc://channel")
else:
    s.bind(endpoint)
time.sleep(1.0)  # the SUB connects (slow joiner)
first = events[0][0]
wall = time.monotonic()
for log_time, topic, body in events:
    due = wall + (log_time - first) / 1e9
    left = due - time.monotonic()
    if left > 0:
        time.sleep(left)
    s.send_multipart([topic, body])
time.sleep(0.5)
print(len(events), flush=True)
"""

MCAP_SUMMARY = """
import sys
from mcap.reader import SeekingReader
with open(sys.argv[1], "rb") as f:
    assert SeekingReader(f).get_summary() is not None
"""

MCAP_ITERATE = """
import sys
from mcap.reader import make_reader
n = 0
with open(sys.argv[1], "rb") as f:
    start, end = int(sys.argv[2]), int(sys.argv[3])
    for _ in make_reader(f).iter_messages(starting_at=start, ending_before=end):
        n += 1
with open("/proc/self/status") as s:
    print(next(l.split()[1] for l in s if l.startswith("VmHWM:")), n)
"""


def spread(values: list[float], scale: float = 1.0, unit: str = "") -> str:
    v = sorted(x * scale for x in values)
    return f"{statistics.median(v):.3f}{unit} ({v[0]:.3f}-{v[-1]:.3f})"


def percentile(values: list[float], p: float) -> float:
    v = sorted(values)
    return v[min(len(v) - 1, int(p * len(v)))]


# ---- the log -------------------------------------------------------------------------------------


def write_big_log(path: Path, events: int) -> None:
    import Miro

    from miro_gen.eventlog.writer import LogWriter
    from miro_gen.transport.events.frames import RawEvent

    h = Miro.ExampleEventIDL  # noqa: F841 - the generated packages, imported
    cls = Miro.ImageEventIDL
    fmt = Miro.ImageFormatIDL(40, 28, Miro.ImageEncodingIDL.IMAGE_MONO8, 40)
    writer = LogWriter(str(path))
    started = time.monotonic()
    for n in range(events):
        t = T0 + n * 1_000_000
        robot = "robot1" if n % 2 == 0 else "robot2"
        seq = n // 2
        payload = cls(Miro.TimeIDL(t // 10**9, t % 10**9 // 1000), seq, fmt, os.urandom(1120))
        writer.write(
            [RawEvent(robot, "Image", cls._type_hash, 1, seq, t, t, payload.serialize())], t
        )
        if n % 1000 == 999:
            writer.flush()  # a chunk of a second's events, as the recorder closes them
        if n % 100_000 == 99_999:
            print(f"  written {n + 1} events, {path.stat().st_size / GIB:.2f} GiB", flush=True)
    writer.finish()
    took = time.monotonic() - started
    print(f"  {events} events, {path.stat().st_size / GIB:.3f} GiB in {took:.0f} s")


# ---- 1. opening ----------------------------------------------------------------------------------


OPEN_BASELINES = {  # each case of bench_open, and the baseline it is measured against
    "mcap library: summary": "mcap library: summary",
    "player model": "mcap library: summary",
    "miro log info": "mcap library: summary",
    "process: mcap summary": "process: mcap summary",
    "process: miro log info": "process: mcap summary",
}


def bench_open(path: Path, repeats: int) -> dict[str, list[float]]:
    from mcap.reader import SeekingReader

    from miro_gen.cli.log import info_main
    from miro_gen.eventlog.fileset import FileSet

    def mcap_summary() -> None:
        with open(path, "rb") as f:
            assert SeekingReader(f).get_summary() is not None

    def model() -> None:
        fs = FileSet()
        fs.add(str(path))
        fs.close()

    def info() -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            assert info_main([str(path)]) == 0

    def mcap_process() -> None:
        subprocess.run([*PYTHON, "-c", MCAP_SUMMARY, str(path)], check=True, env=ENV)

    def info_process() -> None:
        command = [*MIRO, "log", "info", str(path)]
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=ENV)

    in_process = {
        "mcap library: summary": mcap_summary,
        "player model": model,
        "miro log info": info,
    }
    processes = {"process: mcap summary": mcap_process, "process: miro log info": info_process}
    out: dict[str, list[float]] = {name: [] for name in (*in_process, *processes)}
    for _ in range(repeats):
        for cases in (in_process, processes):
            for name, took in alternated(cases).items():
                out[name].append(took)
    return out


def alternated(cases: dict[str, Callable[[], object]], seconds: float = 2.0) -> dict[str, float]:
    """Seconds per call of each case, called in turn (one call of each, again and again) until
    each has had at least `seconds` of calls: a machine whose load changes from one second to
    the next weighs on every case alike, as a case's 2 s run after another's would not."""
    total = dict.fromkeys(cases, 0.0)
    calls = 0
    while min(total.values()) < seconds:
        for name, fn in cases.items():
            started = time.perf_counter()
            fn()
            total[name] += time.perf_counter() - started
        calls += 1
    return {name: took / calls for name, took in total.items()}


# ---- 2. seeks ------------------------------------------------------------------------------------


def start_consumer(
    naming: str, ready: bool = True, env: dict[str, str] = ENV
) -> subprocess.Popen[str]:
    """The consumer process; with `ready`, once it has subscribed (its channel must be bound:
    it waits for it)."""
    c = subprocess.Popen(
        [*PYTHON, "-c", CONSUMER, naming], stdout=subprocess.PIPE, text=True, env=env
    )
    if ready:
        assert c.stdout is not None and c.stdout.readline().strip() == "READY"
    return c


def consumer_records(c: subprocess.Popen[str]) -> list[tuple[int, str, int]]:
    c.send_signal(signal.SIGTERM)
    out, _ = c.communicate(timeout=60)
    return [tuple(json.loads(line)) for line in out.splitlines() if line.startswith("[")]  # type: ignore[misc]


def bench_seek(path: Path, naming: str, repeats: int, per_repeat: int) -> dict[str, list[float]]:
    from mcap.reader import SeekingReader

    from miro_gen import Server
    from miro_gen.eventlog.fileset import FileSet, at_time
    from miro_gen.eventlog.player import Player
    from miro_gen.eventlog.routes import Routes

    sys.setswitchinterval(0.0005)
    server = Server(["bench-player", "--naming", naming, "-MNC", "bench"])
    routes = Routes(server, mode="unified")
    files = FileSet()
    files.add(str(path))
    routes.connect(files.domains())
    reactor = threading.Thread(target=server.run, daemon=True)
    reactor.start()
    player = Player(files, routes.send)
    player.start()
    consumer = start_consumer(naming)
    while not routes.subscribed("robot2", "Image"):
        time.sleep(0.01)
    first, last = files.span()
    rng = random.Random(28)
    out: dict[str, list[float]] = {"end to end": [], "model": [], "mcap library": []}
    seeks: list[tuple[int, tuple[str, int]]] = []
    try:
        player.play()
        for _ in range(repeats):
            for _ in range(per_repeat):
                t = rng.randrange(first, last - 2_000_000_000)
                probe = FileSet()  # its own segments: the player's stay cold for the seek
                probe.add(str(path))
                t0 = time.perf_counter()
                ev = next(probe.forward(at_time(t)))
                out["model"].append(time.perf_counter() - t0)
                probe.close()
                with open(path, "rb") as f:
                    reader = SeekingReader(f)
                    t0 = time.perf_counter()
                    next(iter(reader.iter_messages(starting_at=t)))
                    out["mcap library"].append(time.perf_counter() - t0)
                called = time.time_ns()
                player.seek(t)
                seeks.append((called, (ev.topic.domain, ev.message.sequence)))
                time.sleep(0.25)
    finally:
        player.close()
        records = consumer_records(consumer)
        server.shutdown()
        reactor.join(5)
        files.close()
    for called, (domain, seq) in seeks:
        arrivals = [r for r, d, s in records if d == domain and s == seq and r >= called]
        out["end to end"].append((arrivals[0] - called) / 1e9 if arrivals else float("inf"))
    return out


# ---- 3. and 4. replay timing and memory ----------------------------------------------------------


def rss_sampler(pid: int, peak: list[int], stop: threading.Event) -> None:
    while not stop.is_set():
        try:
            with open(f"/proc/{pid}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        peak[0] = max(peak[0], int(line.split()[1]))
        except OSError:
            return
        stop.wait(0.05)


def deviations(
    records: list[tuple[int, str, int]], log_time: Callable[[str, int], int]
) -> list[float]:
    offsets = [r - log_time(d, s) for r, d, s in records]
    middle = statistics.median(offsets)
    return [abs(o - middle) / 1e6 for o in offsets]


def replay_ours(
    path: Path,
    naming: str,
    start_s: float,
    seconds: float,
    tap: bool,
    env: dict[str, str] = ENV,
    rate: float = 1.0,
) -> tuple[list[float], int, int]:
    """`miro log play` of the span at `rate` into a keep-all StructuredPushConsumer process
    (or, with `tap`, a bare SUB on the channel: the player's own timing); deviations, events,
    peak RSS (kB). `env`: whose miro_gen (`tree_env`) the processes run."""
    unbound(naming, "robot1/EventChannel")  # the last run's player's: a tap would find it
    if tap:
        consumer = subprocess.Popen(
            [*PYTHON, "-c", RAW_TAP, naming], stdout=subprocess.PIPE, text=True, env=env
        )
    else:
        consumer = start_consumer(naming, ready=False, env=env)  # the player binds the channel
    player = subprocess.Popen(
        [
            *MIRO,
            "log",
            "play",
            str(path),
            "--naming",
            naming,
            "-MNC",
            "bench",
            "--unified-channel",
            "--start",
            f"{start_s:.3f}",
            "--end",
            f"{start_s + seconds:.3f}",
            "--rate",
            f"{rate:g}",
            "--wait-subscribed",
        ],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    peak = [0]
    stop = threading.Event()
    sampler = threading.Thread(target=rss_sampler, args=(player.pid, peak, stop), daemon=True)
    sampler.start()
    _, err = player.communicate(timeout=seconds / rate + 120)
    stop.set()
    assert player.returncode == 0, err
    records = consumer_records(consumer)

    def log_time(domain: str, seq: int) -> int:
        return T0 + (2 * seq + (domain == "robot2")) * 1_000_000

    return deviations(records, log_time), len(records), peak[0]


def unbound(naming: str, name: str, seconds: float = 30.0) -> None:
    """Wait until nobody binds `name` (a player that ended unbinds its channels)."""
    import MiroNaming

    from miro_gen.service.server import Client

    client = Client(["bench", "--naming", naming])
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                client.naming.resolve(name)
            except MiroNaming.NotFound:
                return
            time.sleep(0.05)
        raise RuntimeError(f"{name} is still bound after {seconds:g} s")
    finally:
        client.close()


def replay_raw(
    path: Path, start_s: float, seconds: float, proxy: bool = False
) -> tuple[list[float], int]:
    """A bare pyzmq publisher on a sleep loop into a bare SUB (with `proxy`, through an
    XSUB/XPUB proxy thread in the publisher's process: the channel's hop alone)."""
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    sub = subprocess.Popen(
        [*PYTHON, "-c", RAW_SUB, endpoint], stdout=subprocess.PIPE, text=True, env=ENV
    )
    assert sub.stdout is not None and sub.stdout.readline().strip() == "READY"
    start = T0 + int(start_s * 1e9)
    end = start + int(seconds * 1e9)
    subprocess.run(
        [*PYTHON, "-c", RAW_PUB, str(path), str(start), str(end), endpoint]
        + (["proxy"] if proxy else []),
        check=True,
        capture_output=True,
        env=ENV,
        timeout=seconds + 120,
    )
    records = consumer_records(sub)

    def log_time(topic: str, seq: int) -> int:
        return T0 + (2 * seq + (topic.startswith("robot2"))) * 1_000_000

    return deviations(records, log_time), len(records)


def play_rss(path: Path, naming: str, seconds: float, rate: float) -> int:
    """Peak RSS (kB) of `miro log play` of `seconds` of the log at `rate`, into a channel of
    its own with nobody listening (what it reads and holds, not what a consumer costs)."""
    player = subprocess.Popen(
        [*MIRO, "log", "play", str(path), "--naming", naming, "--channel", "benchmem/EventChannel",
         "--rate", str(rate), "--start", "100", "--end", str(100 + seconds)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV,
    )  # fmt: skip
    peak = [0]
    stop = threading.Event()
    sampler = threading.Thread(target=rss_sampler, args=(player.pid, peak, stop), daemon=True)
    sampler.start()
    player.wait(seconds / rate + 120)
    stop.set()
    return peak[0]


def window_rss(path: Path, naming: str, seconds: float) -> int | None:
    try:
        import PySide6  # noqa: F401
    except ImportError:
        return None
    env = dict(ENV, QT_QPA_PLATFORM="offscreen")
    window = subprocess.Popen(
        [
            *MIRO,
            "log",
            "player",
            str(path),
            "--naming",
            naming,
            "-MNC",
            "benchgui",
            "--play",
            "--channel",
            "benchgui/EventChannel",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    peak = [0]
    stop = threading.Event()
    sampler = threading.Thread(target=rss_sampler, args=(window.pid, peak, stop), daemon=True)
    sampler.start()
    time.sleep(seconds)
    stop.set()
    window.terminate()
    window.wait(30)
    return peak[0]


def mcap_iterate_rss(path: Path, start_s: float, seconds: float) -> int:
    start = T0 + int(start_s * 1e9)
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            MCAP_ITERATE,
            str(path),
            str(start),
            str(start + int(seconds * 1e9)),
        ],
        check=True,
        capture_output=True,
        text=True,
        env=ENV,
    ).stdout.split()
    return int(out[0])


# ---- main ----------------------------------------------------------------------------------------


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--events", type=int, default=1_000_000)
    ap.add_argument("--file", type=Path, help="use (or write and keep) this log")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=4.0, help="replayed per timing run")
    ap.add_argument(
        "--before",
        type=Path,
        help="a source tree of the code before a change (`git archive COMMIT | tar -x -C DIR`):"
        " its player's replay rows too, interleaved with this tree's in each repeat",
    )
    ap.add_argument(
        "--parts",
        type=lambda text: text.split(","),
        default=["open", "seek", "replay", "memory"],
        help="which figures, comma-separated (default open,seek,replay,memory; also lossless)",
    )
    args = ap.parse_args()
    folder = tempfile.mkdtemp(prefix="miro-bench-player-")
    path = args.file or Path(folder) / "big.mcap"
    try:
        if not path.exists():
            need = args.events * 1100 + GIB // 4
            free = shutil.disk_usage(path.parent).free
            if free < need * 1.2:
                have = f"{free / GIB:.1f} GiB free, {need / GIB:.1f} GiB needed"
                print(f"not enough disk in {path.parent}: {have}")
                return 1
            print(f"writing {path}")
            write_big_log(path, args.events)
        size = path.stat().st_size
        load = os.getloadavg()[0]
        print(f"log: {size / GIB:.3f} GiB, {args.events} events; load average {load:.2f}")
        return run(path, args)
    finally:
        if args.file is None:
            shutil.rmtree(folder, ignore_errors=True)


def trees_of(args: argparse.Namespace) -> list[tuple[str, dict[str, str]]]:
    """This tree's environment, and with --before the tree before's ("before: ")."""
    trees = [("", ENV)]
    if args.before is not None:
        trees.append(("before: ", tree_env(args.before.resolve())))
    return trees


def run(path: Path, args: argparse.Namespace) -> int:
    port = free_port()
    naming_endpoint = f"tcp://127.0.0.1:{port}"
    naming = subprocess.Popen(
        [*MIRO, "naming", "--endpoint", naming_endpoint], stdout=subprocess.PIPE, text=True, env=ENV
    )
    assert naming.stdout is not None
    naming.stdout.readline()
    failed = False
    peaks: list[int] = []  # the replay runs' peak RSS (kB), shown with the memory figures
    try:
        if "open" in args.parts:
            print("\n1. opening (ms per open, median (min-max) of 5 runs of >= 2 s)")
            opened = bench_open(path, args.repeats)
            for name, times in opened.items():
                baseline = OPEN_BASELINES[name]
                ratio = statistics.median(times) / statistics.median(opened[baseline])
                print(f"  {name:24} {spread(times, 1e3, ' ms')}  {ratio:.2f}x")
                if name != baseline and ratio > 1.5:
                    failed = True
            print(f"  load average {os.getloadavg()[0]:.2f}")

        if "seek" in args.parts:
            print("\n2. seeks while playing at 1x (ms): 5 runs of 10 random seeks")
            seeks = bench_seek(path, naming_endpoint, args.repeats, 10)
            for name, times in seeks.items():
                print(
                    f"  {name:24} p50 {statistics.median(times) * 1e3:7.2f}  p99 "
                    f"{percentile(times, 0.99) * 1e3:7.2f}  max {max(times) * 1e3:7.2f}"
                )
            worst = max(seeks["end to end"])
            failed |= worst > 0.1
            print(f"  every seek's first event within 100 ms: {'yes' if worst <= 0.1 else 'NO'}")
            print(f"  load average {os.getloadavg()[0]:.2f}")

        if "replay" in args.parts:
            print(f"\n3. replay at 1x, 1,000 events/s, {args.seconds:g} s a run (ms)")
            print("   |arrival - log time - their median|, p99, median (min-max) of the runs")
            rng = random.Random(2028)
            span_s = args.events / 1000
            p99: dict[str, list[float]] = {"structured": [], "tap": [], "raw": [], "proxy": []}
            trees = trees_of(args)
            if args.before is not None:
                p99 |= {"before: structured": [], "before: tap": []}
            counts: dict[str, list[int]] = {name: [] for name in p99}
            loads = []
            for _ in range(args.repeats):
                loads.append(os.getloadavg()[0])
                start_s = rng.uniform(0, max(0.0, span_s - args.seconds - 1))
                for which, env in trees:
                    for tap in (False, True):
                        dev, n, peak = replay_ours(
                            path, naming_endpoint, start_s, args.seconds, tap, env
                        )
                        row = which + ("tap" if tap else "structured")
                        p99[row].append(percentile(dev, 0.99))
                        counts[row].append(n)
                        if not which:
                            peaks.append(peak)
                for row, proxy in (("raw", False), ("proxy", True)):
                    rdev, n = replay_raw(path, start_s, args.seconds, proxy)
                    p99[row].append(percentile(rdev, 0.99))
                    counts[row].append(n)
            rows = [
                ("tap", "miro log play, bare SUB"),
                ("structured", "miro log play, consumer"),
                ("raw", "bare pyzmq + sleep, SUB"),
                ("proxy", "bare pyzmq, via a proxy"),
            ]
            if args.before is not None:
                rows[2:2] = [
                    ("before: tap", "before: bare SUB"),
                    ("before: structured", "before: consumer"),
                ]
            for name, label in rows:
                ratio = statistics.median(p99[name]) / statistics.median(p99["raw"])
                got = f"{min(counts[name])}-{max(counts[name])}"
                print(
                    f"  {label:26} p99 {spread(p99[name], 1.0, ' ms')}  {ratio:.2f}x  {got} events"
                )
            failed |= statistics.median(p99["tap"]) > 2.0
            loads.append(os.getloadavg()[0])
            print(f"  load average {min(loads):.2f} to {max(loads):.2f} (at each repeat's start)")

        if "lossless" in args.parts:
            print("\n5. lossless at x32: 10 s of the log (10,001 events) into a keep-all consumer")
            got: dict[str, list[int]] = {}
            loads = []
            for _ in range(args.repeats):
                loads.append(os.getloadavg()[0])
                start_s = random.uniform(0, max(0.0, args.events / 1000 - 11))
                for which, env in trees_of(args):
                    _, n, _ = replay_ours(
                        path, naming_endpoint, start_s, 10.0, False, env, rate=32.0
                    )
                    got.setdefault(which or "this tree", []).append(n)
            for which, counts in got.items():
                print(f"  {which:24} received {', '.join(map(str, counts))} of 10001")
            failed |= any(n != 10_001 for n in got["this tree"])
            loads.append(os.getloadavg()[0])
            print(f"  load average {min(loads):.2f} to {max(loads):.2f} (at each repeat's start)")

        if "memory" in args.parts:
            print("\n4. resident memory while playing (MB, peak)")
            if peaks:
                print(
                    f"  miro log play, 4 s at 1x  {spread([p / 1024 for p in peaks], 1.0, ' MB')}"
                )
            long_peak = play_rss(path, naming_endpoint, 300.0, 32.0)
            print(f"  miro log play, 300 s x32  {long_peak / 1024:.1f} MB")
            gui = window_rss(path, naming_endpoint, 8.0)
            if gui is not None:
                print(f"  miro log player (window)  {gui / 1024:.1f} MB")
            base_rss = mcap_iterate_rss(path, 0.0, args.seconds)
            print(f"  mcap library iterating    {base_rss / 1024:.1f} MB (the same span)")
            failed |= max([*peaks, long_peak]) / 1024 > 200
            print(f"  load average {os.getloadavg()[0]:.2f}")
    finally:
        naming.kill()
        naming.wait()
    print("\nall targets met" if not failed else "\nsome target MISSED")
    return 0


if __name__ == "__main__":
    sys.exit(main())
