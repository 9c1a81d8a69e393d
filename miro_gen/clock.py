"""The runtime's clock: wall time, or the replayed time of a log player (`--clock log`).

Miro's promise for logs is that an algorithm runs the same on the vehicle and on a replay. An
algorithm that asks `miro_gen.clock.now()` for the time and uses reactor timers for its periods
does: in a process started with `--clock log`, both follow the player's clock, so a filter that
publishes at 10 Hz does so at 10 Hz of *log* time at any `--rate`, stops while the player is
paused, and moves one event at a time while it steps.

A clock gives the reactor its time base (`timer_time()`) and how long, in real seconds, that
base takes to advance by a given amount (`real_delay()`, None while it stands still). When the
time jumps (the first clock message, a loop back to the start), listeners are told by how much,
and the reactor moves its timers with it, so a periodic timer keeps its phase and rate.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import NamedTuple

Listener = Callable[[float], object]  # called with the jump of timer time, in seconds
# Seconds after a player's last clock message that a follower stops extrapolating its time. A
# player publishes its clock every half second while it plays (eventlog.player.CLOCK_PERIOD):
# without this bound, a follower of a player that was killed, or whose last message (its pause
# at the end of the log) was lost as it exited, ran on past the log's end for ever.
STALE = 2.0


class Clock:
    """Wall time: `now()` is `time.time()`, timers run on `time.monotonic()`."""

    def __init__(self) -> None:
        self._listeners: list[Listener] = []

    def now(self) -> float:
        """Seconds since the Unix epoch."""
        return time.time()

    def time_ns(self) -> int:
        return time.time_ns()

    def timer_time(self) -> float:
        """The time base of reactor timers, in seconds."""
        return time.monotonic()

    def real_delay(self, seconds: float) -> float | None:
        """Real seconds until `timer_time()` has advanced by `seconds`; None when it is not
        advancing (the reactor then waits to be woken by a change)."""
        return seconds

    def add_listener(self, listener: Listener) -> None:
        """Call `listener(jump)` on every change of the clock (jump 0 when only its rate or
        pause changed)."""
        self._listeners.append(listener)

    def _changed(self, jump: float) -> None:
        for listener in list(self._listeners):
            listener(jump)


class _State(NamedTuple):
    started: bool
    log_ns: int  # log time at the anchor
    anchor: float  # time.monotonic() at the anchor
    rate: float
    paused: bool
    epoch: int
    floor: int = 0  # the time stands here until the player's passes it (a player held back)


class LogClock(Clock):
    """The replayed time of a log player, extrapolated between its clock messages. Until the
    first one arrives, time stands still (at 0): timers wait for the player.

    Time never runs backwards within an epoch: a message behind the time this clock has
    reached (a player whose events were held back by a slow keep-all consumer, or that was
    not scheduled for a while, sets its clock back to the event it sends) makes it stand still
    until the player's time passes it, rather than run on ahead of the replay. And it runs on
    from a message for STALE seconds at most: then it stands until the next one."""

    def __init__(self) -> None:
        super().__init__()
        self._state = _State(False, 0, time.monotonic(), 1.0, True, 0)
        self._lock = threading.Lock()

    @staticmethod
    def _player_at(s: _State, mono: float) -> int:
        """The player's time, as its last message says."""
        if s.paused or not s.started:
            return s.log_ns
        return s.log_ns + int(min(mono - s.anchor, STALE) * s.rate * 1e9)

    @classmethod
    def _at(cls, s: _State, mono: float) -> int:
        return max(cls._player_at(s, mono), s.floor)

    def time_ns(self) -> int:
        return self._at(self._state, time.monotonic())

    def now(self) -> float:
        return self.time_ns() / 1e9

    def timer_time(self) -> float:
        return self.time_ns() / 1e9

    def real_delay(self, seconds: float) -> float | None:
        s = self._state
        if s.paused or not s.started:
            return None
        mono = time.monotonic()
        behind = max(0, s.floor - self._player_at(s, mono)) / 1e9  # standing
        delay = (max(0.0, seconds) + behind) / s.rate
        vouched = s.anchor + STALE - mono  # real seconds the last message still covers
        if delay <= vouched:
            return delay
        return vouched if vouched > 0 else None  # then it stands until the next message

    @property
    def started(self) -> bool:
        return self._state.started

    @property
    def paused(self) -> bool:
        return self._state.paused

    def update(self, log_time_ns: int, rate: float, paused: bool, epoch: int) -> None:
        """A clock message from the player: log time was `log_time_ns` when it was sent."""
        if not rate > 0:
            return
        with self._lock:
            mono = time.monotonic()
            old = self._state
            predicted = self._at(old, mono)
            jump = 0.0
            floor = 0
            if not old.started or epoch != old.epoch:
                jump = (log_time_ns - predicted) / 1e9
            elif log_time_ns < predicted:
                # Never backwards (the message took a while to come, or the player was held
                # back): stand still until the player's time passes the time reached.
                floor = predicted
            self._state = _State(True, log_time_ns, mono, rate, paused, epoch, floor)
        self._changed(jump)


_clock: Clock = Clock()


def current() -> Clock:
    """The process's clock."""
    return _clock


def use(clock: Clock) -> None:
    """Make `clock` the process's clock (the Server does, for `--clock log`)."""
    global _clock
    _clock = clock


def now() -> float:
    """The time, in seconds since the Unix epoch: the replayed one under `--clock log`."""
    return _clock.now()
