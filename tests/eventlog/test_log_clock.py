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

from miro_gen.clock import STALE, LogClock
from miro_gen.eventlog.writer import LogWriter
from miro_gen.transport.events.frames import RawEvent
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
    eventually(lambda: clock.now() >= T0 / 1e9 + 2.5, 30)
    # Counted in log time, which a loaded machine cannot bend: never early, at most one run a
    # period (a late run skips those it covers), and more than half of the 20 periods of the
    # first 2 log seconds had theirs; a timer on wall time would have run 5 times.
    assert fired[0] >= T0 / 1e9 + 0.1
    assert fired == sorted(fired)
    first_two = [t for t in fired if t <= T0 / 1e9 + 2.0]
    assert 10 < len(first_two) <= 20, first_two


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
    back_to = T0 / 1e9 - 10
    clock.update(T0 - 10 * 10**9, 1.0, False, 1)  # the player looped back to 10 s before T0
    eventually(lambda: len(fired) >= count + 3 and clock.now() >= back_to + 0.5, 30)
    back = fired[count + 1 :]  # (the run at `count` may have been under way at the pause)
    assert back and all(back_to <= t < T0 / 1e9 for t in back)  # on the earlier time
    # ... at its period, not catching up: at most one run in each 0.1 s of its first 0.5 s.
    assert len([t for t in back if t <= back_to + 0.5]) <= 6


def test_a_clock_set_back_stands_still_until_the_player_passes_it() -> None:
    """A player whose sends were held back (a slow keep-all consumer, a thread not scheduled
    for a while) sets its clock back to the event it sends, in the same epoch. A follower
    neither goes backwards nor runs on ahead of the replay (it did: a process on --clock log
    stamped its events with log time past the log's end): it stands still until the player's
    time passes the time it had reached, and follows it from there."""
    clock = LogClock()
    clock.update(T0, 1.0, False, 0)
    eventually(lambda: clock.time_ns() >= T0 + 300_000_000, 30)
    clock.update(T0, 0.001, False, 0)  # set back by 0.3 s or more, at a crawl: 300 s behind
    reached = clock.time_ns()
    assert reached >= T0 + 300_000_000
    time.sleep(0.1)
    assert clock.time_ns() == reached  # standing, not running on from where it was
    clock.update(T0 + 2 * 10**9, 1.0, False, 0)  # the player passed it: followed again
    assert clock.time_ns() >= T0 + 2 * 10**9
    assert clock.real_delay(0.5) == 0.5
    clock.update(T0 + 10**9, 1.0, True, 0)  # paused behind it: stands where it was
    assert clock.time_ns() >= T0 + 2 * 10**9 and clock.real_delay(0.1) is None


def test_a_follower_whose_player_went_silent_stands_still() -> None:
    """A player publishes its clock every half second while it plays. One that was killed, or
    whose last message (its pause at the end of the log) was lost as it exited, left its
    followers running on past the log's end for ever; now they stand STALE seconds after the
    last message until the next one comes."""
    clock = LogClock()
    clock.update(T0, 1.0, False, 0)
    assert clock.real_delay(0.5) == 0.5
    eventually(lambda: clock.real_delay(0.001) is None, 30)
    assert clock.time_ns() == T0 + int(STALE * 1e9)
    clock.update(T0 + 3 * 10**9, 1.0, False, 0)  # the player again: followed from there
    assert clock.time_ns() >= T0 + 3 * 10**9 and clock.real_delay(0.5) == 0.5


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
    ticks = replay_with_follower(log)
    stamps = [(t["stamp"] - T0) / 1e9 for t in ticks]  # log seconds from the log's start
    # Log time, not wall time (2020, not now): from the log's start to past its end by what
    # the follower runs on before the player's pause at the end reaches it (at most STALE
    # seconds at 4x, should that message be lost), never backwards.
    assert stamps and all(0 <= s <= 8 + STALE * 4 for s in stamps), stamps
    assert stamps == sorted(stamps), stamps
    # 10 a logged second, not the 2.5 of a timer on wall time under a 4x replay, counted
    # rather than timed: at most one each 0.1 s of the log time it reached (a tick that a
    # loaded machine delays skips those it covers; its stamp may fall in the next period),
    # and most 0.1 s of log time after the one before (the median gap: a loaded machine that
    # holds the process back now and then widens some gaps; a wall-time timer's are 0.4 s),
    # over a quarter of the log at least (it may find the player's clock late).
    said = f"{len(stamps)} ticks from {stamps[0]} to {stamps[-1]} s: {stamps}"
    assert len(stamps) <= stamps[-1] / 0.1 + 0.5, said
    assert stamps[-1] - stamps[0] >= 2, said
    gaps = sorted(b - a for a, b in itertools.pairwise(stamps))
    assert gaps[len(gaps) // 2] < 0.2, said


def test_the_clock_option_is_checked() -> None:
    from miro_gen.service.options import UsageError, parse_common_options

    opts, rest = parse_common_options(["--clock", "log:robot1/LogClock", "x"])
    assert opts.clock == "log:robot1/LogClock" and rest == ["x"]
    assert parse_common_options(["--clock=log"])[0].clock == "log"
    assert parse_common_options([])[0].clock == "wall"
    for bad in ("ros", "log:", "log:/"):
        with pytest.raises(UsageError, match="--clock takes wall, log or log:CHANNEL"):
            parse_common_options(["--clock", bad])
