"""Where the log player's late events come from (issue 28, the 2 ms figure): one replay at 1x,
each event's lateness logged with its index and what happened around it.

    python bench/trace_replay.py [--file PATH] [--events 20000] [--seconds 4] [--runs 3]

Runs what `miro log play --unified-channel` runs (a Server, the Routes, the Player, the clock
publisher, the reactor's thread), in this process, into the bare SUB of bench_logplayer (its
RAW_TAP, a process of its own, arrivals on the wall clock), and records per event: when the
player's thread called `send` and when it returned (time.time_ns), the log time. Beside it:
every garbage collection (gc.callbacks: start, stop, generation) and every segment decoded
(eventlog.segments._decode: which thread, start, stop), every call into the direct link that
waited for its lock (the reactor holding it).

An event's lateness is its arrival minus its log offset, against the run's median of that (as
the bench's p99); its *send lateness* the same for the moment `send` was called; the hop is
arrival minus send. The events over `--late` ms (default 2) are put down to the first cause
that explains them, in this order:

- `send late, GC`: sent late, and a collection ran between the previous event's send and this;
- `send late, decode`: sent late while (or just after) a segment was decoded on any thread;
- `send late, lock`: sent on time but the send call itself took > 0.5 ms (the link's lock);
- `send late, other`: sent late, none of the above;
- `hop`: sent on time, arrived late (the channel's proxy thread, the receiver).
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_logplayer as bl


def run_delay() -> int:
    """ns this thread has waited for a core (runnable, not running) since it started."""
    with open("/proc/thread-self/schedstat") as f:
        return int(f.read().split()[1])


def trace_once(
    path: Path, naming: str, start_s: float, seconds: float, late_ms: float, freeze: bool
) -> None:
    import miro_gen.eventlog.segments as segments
    from miro_gen.eventlog.fileset import FileSet
    from miro_gen.eventlog.player import Player, pace_process
    from miro_gen.eventlog.routes import ClockPublisher, Routes
    from miro_gen.service.server import Server
    from miro_gen.transport.events.links import ZmqPublishing

    bl.unbound(naming, "robot1/EventChannel")
    tap = subprocess.Popen(
        [*bl.PYTHON, "-c", bl.RAW_TAP, naming], stdout=subprocess.PIPE, text=True, env=bl.ENV
    )
    gcs: list[tuple[int, int, int, str]] = []  # start, stop, generation, thread
    gc_start = [0]

    def on_gc(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            gc_start[0] = time.time_ns()
        else:
            thread = threading.current_thread().name
            gcs.append((gc_start[0], time.time_ns(), info["generation"], thread))

    decodes: list[tuple[str, int, int, int]] = []  # thread, start, stop, segment offset
    decode = segments._decode

    def timed_decode(log: Any, seg: Any) -> Any:
        t = time.time_ns()
        try:
            return decode(log, seg)
        finally:
            decodes.append((threading.current_thread().name, t, time.time_ns(), seg.offset))

    segments._decode = timed_decode
    lock_waits: list[tuple[int, int]] = []
    send_direct = ZmqPublishing._send_direct

    def timed_send_direct(self: Any, topic: bytes, body: bytes, copy: bool) -> bool:
        t = time.time_ns()
        acquired = self.lock.acquire(blocking=False)
        if acquired:
            self.lock.release()
        else:
            self.lock.acquire()
            self.lock.release()
            lock_waits.append((t, time.time_ns()))
        return bool(send_direct(self, topic, body, copy))

    ZmqPublishing._send_direct = timed_send_direct  # type: ignore[method-assign]
    sends: list[tuple[int, int, int, tuple[int, int, int, int], int]] = []
    files = FileSet()
    files.add(str(path))
    t0 = files.span()[0]
    files.cut_front(t0 + int(start_s * 1e9))
    files.cut_back(t0 + int((start_s + seconds) * 1e9))
    server = Server(["trace", "--naming", naming, "-MNC", "bench"])
    routes = Routes(server, "EventChannel", "unified")
    assert not routes.connect(files.domains())
    clock = ClockPublisher(server)
    reactor = threading.Thread(target=server.run, daemon=True)
    reactor.start()

    def send(event: Any) -> None:
        t = time.time_ns()
        waited = run_delay()
        routes.send(event)
        sends.append((t, time.time_ns(), event.log_time, event.key, waited))

    player = Player(files, send, clock)
    assert tap.stdout is not None and tap.stdout.readline().strip() == "READY"
    while not routes.subscribed("robot1", "Image"):
        time.sleep(0.02)
    time.sleep(0.5)
    if freeze:
        gc.collect()
        started = time.perf_counter()
        gc.collect()  # a full collection as the player's process had them (nothing to free)
        before = time.perf_counter() - started
        pace_process()  # what `miro log play` does before it plays
        gc.collect()
        gc.freeze()  # the long-lived objects out of the collector (tried, not kept)
        started = time.perf_counter()
        gc.collect()
        after = time.perf_counter() - started
        print(
            f"  a full collection: {before * 1e3:.1f} ms, "
            f"{after * 1e3:.2f} ms frozen ({len(gc.get_objects())} objects tracked, "
            f"{gc.get_freeze_count()} frozen)"
        )
    else:  # what it does
        pace_process()
    gc.callbacks.append(on_gc)
    player.start()
    player.play()
    player.ended.wait(seconds + 60)
    gc.callbacks.remove(on_gc)
    player.close()
    time.sleep(0.3)
    server.shutdown()
    reactor.join(5)
    files.close()
    segments._decode = decode
    ZmqPublishing._send_direct = send_direct  # type: ignore[method-assign]
    arrivals = {(d, s): t for t, d, s in bl.consumer_records(tap)}
    report(sends, arrivals, gcs, decodes, lock_waits, late_ms)


def report(
    sends: list[tuple[int, int, int, tuple[int, int, int, int], int]],
    arrivals: dict[tuple[str, int], int],
    gcs: list[tuple[int, int, int, str]],
    decodes: list[tuple[str, int, int, int]],
    lock_waits: list[tuple[int, int]],
    late_ms: float,
) -> None:
    first_log = sends[0][2]
    base_send = statistics.median(s - (lt - first_log) for s, _, lt, _, _ in sends)
    matched = []
    for i, (s, e, lt, key, delay) in enumerate(sends):
        n = (lt - bl.T0) // 1_000_000  # the bench's log: event n at T0 + n ms, robots in turn
        t = arrivals.get(("robot2" if n % 2 else "robot1", n // 2))
        if t is not None:
            matched.append((i, s, e, lt, key, delay, t))
    base_arr = statistics.median(t - (lt - first_log) for _, _, _, lt, _, _, t in matched)
    lateness = []
    episodes: list[list[tuple[Any, ...]]] = []  # runs of events sent late one after another
    late_run: list[tuple[Any, ...]] = []
    hops = 0
    prev_end, prev_delay = sends[0][1], sends[0][4]
    for i, s, e, lt, key, delay, t in matched:
        late = (t - (lt - first_log) - base_arr) / 1e6
        send_late = (s - (lt - first_log) - base_send) / 1e6
        lateness.append(abs(late))
        if send_late > late_ms / 2 or (e - s) / 1e6 > late_ms / 2:
            late_run.append((i, s, e, key, late, send_late, prev_end, delay - prev_delay))
        else:
            if late_run:
                episodes.append(late_run)
                late_run = []
            if abs(late) > late_ms:
                hops += 1
        prev_end, prev_delay = e, delay
    if late_run:
        episodes.append(late_run)
    lateness.sort()
    p99 = lateness[min(len(lateness) - 1, int(0.99 * len(lateness)))]
    over = sum(1 for x in lateness if x > late_ms)
    gc_by = Counter((g[2], g[3]) for g in gcs)
    print(
        f"  {len(sends)} sent, {len(matched)} arrived; p99 {p99:.2f} ms; {over} over "
        f"{late_ms:g} ms; GCs (generation, thread) {dict(gc_by)} "
        f"(longest {max((g[1] - g[0] for g in gcs), default=0) / 1e6:.2f} ms); "
        f"{len(decodes)} segments decoded "
        f"({dict(Counter(d[0] for d in decodes))}, longest "
        f"{max((d[2] - d[1] for d in decodes), default=0) / 1e6:.1f} ms); "
        f"{len(lock_waits)} lock waits"
    )
    print(
        f"    {over - hops} late from {len(episodes)} late sends (runs of events sent late "
        f"one after another), {hops} sent on time and late on the way (the hop)"
    )
    causes: Counter[str] = Counter()
    rows = []
    for run in episodes:
        first, last = run[0], run[-1]
        lo, hi = first[6], last[1]  # from the send before the run to its last send
        gc_ms = sum(min(g[1], hi) - max(g[0], lo) for g in gcs if g[1] > lo and g[0] < hi) / 1e6
        gens = {(g[2], g[3]) for g in gcs if g[1] > lo and g[0] < hi}
        dec_ms = sum(min(d[2], hi) - max(d[1], lo) for d in decodes if d[2] > lo and d[1] < hi)
        dec_ms /= 1e6
        runq_ms = sum(r[7] for r in run) / 1e6
        peak = max(r[5] for r in run)
        boundary = any(r[3][2] != first[3][2] for r in run) or first[3][3] < 5
        call_ms = max((r[2] - r[1]) for r in run) / 1e6
        late_events = sum(1 for r in run if abs(r[4]) > late_ms)
        if gc_ms >= peak / 3:
            cause = "GC " + ",".join(f"gen {g} on {t}" for g, t in sorted(gens))
        elif runq_ms >= peak / 3:
            cause = "no core (the thread runnable, not running)"
        elif dec_ms > 0:
            cause = "a segment decoded meanwhile"
        elif call_ms >= peak / 3:
            cause = "the send call itself"
        else:
            cause = "none seen (the interpreter's lock? a late wake-up?)"
        causes[cause.split(" on ")[0] if cause.startswith("GC") else cause] += late_events
        rows.append(
            (
                peak,
                first[0],
                len(run),
                late_events,
                gc_ms,
                dec_ms,
                runq_ms,
                call_ms,
                boundary,
                cause,
            )
        )
    for cause, n in causes.most_common():
        print(f"    {n:5d} late events after: {cause}")
    print(
        "    worst late sends: first index, events, late ones, peak ms; within it ms of GC, of "
        "decoding, of waiting for a core, longest send call; a chunk boundary in it; cause"
    )
    for peak, i, n, late_events, gc_ms, dec_ms, runq_ms, call_ms, boundary, cause in sorted(
        rows, reverse=True
    )[:10]:
        print(
            f"    {i:5d} {n:4d} {late_events:4d} {peak:7.2f}  GC {gc_ms:6.2f} dec {dec_ms:6.2f} "
            f"runq {runq_ms:6.2f} call {call_ms:5.2f} {'B' if boundary else '-'} {cause}"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--events", type=int, default=20_000)
    ap.add_argument("--file", type=Path)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--late", type=float, default=2.0, help="ms counted as late")
    ap.add_argument(
        "--gc",
        choices=("both", "freeze", "as-is"),
        default="both",
        help="the objects made before playing frozen out of the collector (gc.freeze), "
        "or not (as `miro log play`), or each in turn (default)",
    )
    args = ap.parse_args()
    folder = tempfile.mkdtemp(prefix="miro-trace-replay-")
    path = args.file or Path(folder) / "log.mcap"
    if not path.exists():
        bl.write_big_log(path, args.events)
    naming_endpoint = f"tcp://127.0.0.1:{bl.free_port()}"
    naming = subprocess.Popen(
        [*bl.MIRO, "naming", "--endpoint", naming_endpoint],
        stdout=subprocess.PIPE,
        text=True,
        env=bl.ENV,
    )
    assert naming.stdout is not None
    naming.stdout.readline()
    try:
        import random

        rng = random.Random(2028)
        for n in range(args.runs):
            start_s = rng.uniform(0, max(0.0, args.events / 1000 - args.seconds - 1))
            for freeze in (False, True) if args.gc == "both" else (args.gc == "freeze",):
                how = "frozen (gc.freeze)" if freeze else "not frozen"
                load = os.getloadavg()[0]
                print(f"run {n + 1}, {how}, load {load:.2f}, from {start_s:.1f} s")
                trace_once(path, naming_endpoint, start_s, args.seconds, args.late, freeze)
    finally:
        naming.kill()
        naming.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
