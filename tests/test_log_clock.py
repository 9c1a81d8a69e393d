"""`--clock log`: timers and now() follow a log player's clock, at any replay rate.

First the reactor on a LogClock fed by hand (no player): timers wait for the clock, run at the
clock's rate, stop while it is paused and keep their phase across a jump. Then end to end: a
process started with `--clock log` publishes every 0.1 s from a reactor timer while
`miro log play --rate 4` replays a log; a consumer process counts 10 of its events per logged
second, received four times as fast as they were logged.
"""

from __future__ import annotations

import itertools
import signal
import statistics
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import Miro
import pytest
import zmq
from eventlog_helpers import proc, read_events, stop
from loopback import NamingProcess, eventually, run_miro

from miro_gen.clock import LogClock
from miro_gen.eventlog.writer import LogWriter
from miro_gen.transport.event_frames import RawEvent
from miro_gen.transport.reactor import Reactor

T0 = 1_577_836_800_000_000_000  # 2020-01-01 00:00:00 UTC: log time is not wall time


@pytest.fixture
def clocked() -> Iterator[tuple[Reactor, LogClock]]:
    clock = LogClock()
    reactor = Reactor(zmq.Context(), clock)
    thread = threading.Thread(target=reactor.run, daemon=True)
    thread.start()
    yield reactor, clock
    reactor.stop()
    thread.join(5)
    reactor.close()


def test_timers_wait_for_the_clock_and_run_at_its_rate(
    clocked: tuple[Reactor, LogClock],
) -> None:
    reactor, clock = clocked
    fired: list[float] = []
    reactor.schedule_timer(0.1, 0.1, lambda _: fired.append(clock.now()))
    time.sleep(0.3)
    assert fired == []  # no player yet: time stands still
    clock.update(T0, 4.0, False, 0)
    started = time.monotonic()
    eventually(lambda: len(fired) >= 20)
    wall = time.monotonic() - started
    assert 0.4 < wall < 1.0  # 2 s of log time at 4x
    assert fired[0] >= T0 / 1e9 + 0.1
    periods = [b - a for a, b in itertools.pairwise(fired[:20])]
    assert abs(statistics.mean(periods) - 0.1) < 0.01  # 0.1 s of log time, not of wall time


def test_pause_stops_timers_and_a_jump_keeps_their_phase(
    clocked: tuple[Reactor, LogClock],
) -> None:
    reactor, clock = clocked
    fired: list[float] = []
    clock.update(T0, 1.0, False, 0)
    reactor.schedule_timer(0.05, 0.1, lambda _: fired.append(clock.now()))
    eventually(lambda: len(fired) >= 2)
    clock.update(clock.time_ns(), 1.0, True, 0)
    count = len(fired)
    frozen = clock.now()
    time.sleep(0.35)
    assert len(fired) in (count, count + 1) and clock.now() == frozen
    clock.update(T0 - 10**9, 1.0, False, 1)  # the player looped back a second before T0
    eventually(lambda: len(fired) >= count + 3)
    assert fired[-1] < T0 / 1e9  # now running on the earlier time
    assert abs((fired[-1] - fired[-2]) - 0.1) < 0.03


def synthetic_log(path: Path, seconds: float) -> None:
    """A log of ExampleEvents every 0.25 s for `seconds`, logged at 2020-01-01."""
    writer = LogWriter(str(path))
    for n in range(int(seconds * 4) + 1):
        t = T0 + n * 250_000_000
        data = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL()).serialize()
        h = Miro.ExampleEventIDL._type_hash
        writer.write([RawEvent("robot1", "ExampleEvent", h, 1, n, t, t, data)], t)
    writer.finish()


def replay_with_follower(log: Path) -> list[dict[str, Any]]:
    """Replay `log` at 4x while a --clock log process publishes every 0.1 s; its events, as a
    consumer process received them."""
    naming = NamingProcess(options=("--channel", "EventChannel"))
    started = []
    try:
        common = ("--naming", naming.endpoint)
        clock = ("--clock", "log:robot1/LogClock")
        publisher = proc("clocked_publisher.py", *common, "-MNC", "robot7", *clock, "0.1")
        started.append(publisher)
        printer = proc("event_printer.py", *common, "-MNC", "gui", "EventChannel", "robot7/Tick")
        started.append(printer)
        for p in (publisher, printer):
            assert p.stdout is not None and p.stdout.readline().strip() == "READY"
        play = run_miro(
            "log", "play", str(log), *common, "-MNC", "robot1", "--rate", "4", "--wait", "1"
        )
        assert play.returncode == 0, play.stderr
        time.sleep(0.5)
        out, _ = stop(printer, signal.SIGTERM)
    finally:
        for p in started:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.communicate(timeout=10)
        naming.stop()
    return read_events(out)


def test_a_process_on_log_time_publishes_10_events_per_logged_second_at_4x(
    tmp_path: Path,
) -> None:
    log = tmp_path / "eight_seconds.mcap"
    synthetic_log(log, 8)
    for _ in range(2):  # a loaded machine may stall the publisher past a tick: once more then
        ticks = replay_with_follower(log)
        stamps = [t["stamp"] / 1e9 for t in ticks]
        assert len(stamps) > 60, f"only {len(stamps)} events"
        assert all(T0 / 1e9 <= s <= T0 / 1e9 + 8.2 for s in stamps)  # log time, not wall time
        # Logged seconds with edges half-way between ticks: 10 events in each full one.
        edge = stamps[0] + 0.05
        counts = [sum(edge + k <= s < edge + k + 1 for s in stamps) for k in range(6)]
        if counts == [10] * 6:
            break
    assert counts == [10] * 6, counts
    # ... and they came four times as fast as they were logged.
    received = [t["received"] / 1e9 for t in ticks]
    speed = (stamps[-1] - stamps[0]) / (received[-1] - received[0])
    assert 3.5 < speed < 4.5, speed


def test_the_clock_option_is_checked() -> None:
    from miro_gen.transport.options import UsageError, parse_common_options

    opts, rest = parse_common_options(["--clock", "log:robot1/LogClock", "x"])
    assert opts.clock == "log:robot1/LogClock" and rest == ["x"]
    assert parse_common_options(["--clock=log"])[0].clock == "log"
    assert parse_common_options([])[0].clock == "wall"
    for bad in ("ros", "log:", "log:/"):
        with pytest.raises(UsageError, match="--clock takes wall, log or log:CHANNEL"):
            parse_common_options(["--clock", bad])
