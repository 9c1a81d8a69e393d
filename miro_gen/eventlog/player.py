"""Miro's LogPlayer: play a file set's events with their original spacing (the model behind
`miro log play` and the player window, with no channel and no Qt in it).

The player keeps a *log clock*: log time advances from an anchor at `rate` log seconds per
second, or stands still while paused. Its *position* is a key of the file set
(eventlog.fileset): the events at or after it are ahead. A thread of its own reads the set
from the position on and hands each event to `send` when the clock reaches the event's log
time (it sleeps until just before, then spins: SPIN), skipping the topics excluded at that
moment. Everything else only changes the state
and wakes that thread, from any thread (the window's, the terminal's key reader):

- `play`, `pause`, `toggle`; `stop` pauses and goes back to the start of the cut;
- `seek(log_ns)` at any moment, playing or paused; `set_rate` while playing;
- `next()` pauses and sends the next event; `prev()` pauses and sends the event before the
  one last sent (Miro's Prev: a step back, which consumers see as that event again);
- a change of the file set (a file opened or closed, a cut) moves the position into what is
  left and plays on from there.

The clock is handed to `publish_clock` whenever it changes (and every CLOCK_PERIOD s), with an
`epoch` that counts its jumps (seeks, steps back, loops), so that processes started with
`--clock log` follow the replayed time (miro_gen.clock). The last `history` events sent are
kept for the event list (`EventHistory`), and the last of each topic in `latest`.

`send` may hold the thread: a keep-all consumer of the host that has not returned its credits
(eventlog.replay). Then the clock waits for the events, not they for it: once an event leaves
more than HELD s of wall time after it was due, the clock is set back to its log time (and
published), so that the clock and the position shown say where the replay is; `held` says so
for a second, and `pace()` the log seconds played per second meanwhile.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from miro_gen.eventlog.fileset import Event, FileSet, Key, TopicName, after, at_time
from miro_gen.eventlog.reader import LogError, Topic
from miro_gen.log import logger

CLOCK_PERIOD = 0.5  # seconds between clock messages while nothing changes
MAX_WAIT = 0.1  # seconds the play thread sleeps at most (its clock ticks, a close is seen)
# Seconds before an event is due that the play thread stops sleeping and spins: a thread that
# sleeps to the very moment wakes up a tenth of a millisecond late or more (the timer's slack,
# the scheduler, a core waking up), one that spins is there. Short, since the spin costs a
# core that share of the time (a fifth of it at 1,000 events a second), which the consumers on
# the same machine may want.
SPIN = 0.0002
DEFAULT_HISTORY = 100
# Seconds an event may leave after it was due before the clock waits for it. Shorter holds (a
# keep-all consumer not scheduled for a while) are caught up, as a live supplier's queue would
# be, so that the rest of the replay keeps its place in time; longer ones are not pretended away.
HELD = 0.2
HELD_SHOWN = 1.0  # seconds `held` stays true after the clock last waited
SWITCH_INTERVAL = 0.0001  # seconds a thread holds the interpreter before another may take it
RATES = (1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)  # the speed dial's steps
SKIP = 1 / 20  # of the cut's length: how far a skip (shift+arrow) seeks
MAX_HISTORY = 100_000
_SEND, _SKIP, _RESTART, _CLOSED = range(4)


class Row(NamedTuple):
    """An event as the event list keeps it: where it is and what it is, not its payload (a
    history of camera images would hold gigabytes)."""

    key: Key
    topic: Topic
    sequence: int
    size: int  # bytes of its payload

    @property
    def log_time(self) -> int:
        return self.key[0]

    @property
    def name(self) -> TopicName:
        return (self.topic.domain, self.topic.type_name)


def row_of(event: Event) -> Row:
    return Row(event.key, event.topic, event.message.sequence, len(event.message.data))


@dataclass(frozen=True)
class ClockState:
    """Where the log clock stands: `log_ns` now, advancing at `rate` unless `paused`."""

    log_ns: int
    rate: float
    paused: bool
    epoch: int


class EventHistory:
    """The last `length` events sent, oldest first, as rows for the event list. After a seek
    it holds the events before the new position, read (when asked for) from the file set."""

    def __init__(self, files: FileSet, length: int = DEFAULT_HISTORY) -> None:
        self.files = files
        self._lock = threading.Lock()
        self._rows: deque[Row] = deque(maxlen=_check_length(length))
        self._fill_before: Key | None = None  # read the events before this key when asked
        self.version = 0  # changes whenever the rows do

    @property
    def length(self) -> int:
        return self._rows.maxlen or 0

    def set_length(self, length: int) -> None:
        """Keep `length` events: fewer drops the oldest, more reads older ones when asked."""
        with self._lock:
            rows = list(self._rows)
            self._rows = deque(rows[-_check_length(length) :], maxlen=length)
            if len(self._rows) < length and self._fill_before is None:
                self._fill_before = rows[0].key if rows else None
            self.version += 1

    def append(self, event: Event) -> None:
        row = row_of(event)
        with self._lock:
            self._rows.append(row)
            self.version += 1

    def restart(self, pos: Key) -> None:
        """The position jumped to `pos`: the rows become the events before it."""
        with self._lock:
            self._rows.clear()
            self._fill_before = pos
            self.version += 1

    def rows(self) -> list[Row]:
        """The events, oldest first, excluded topics left out (reads the file set after a
        seek or a longer history: call it from the thread that shows them)."""
        with self._lock:
            fill, self._fill_before = self._fill_before, None
            missing = self.length - len(self._rows)
        if fill is not None and missing > 0:
            older: list[Row] = []
            start = self.files.cut[0]
            try:
                for ev in self.files.backward(fill, start):
                    older.append(row_of(ev))
                    if len(older) >= missing:
                        break
            except LogError:
                pass  # the player reports the damaged segment when it comes to it
            with self._lock:
                kept = [e for e in self._rows if not older or e.key > older[0].key]
                self._rows = deque([*reversed(older), *kept], maxlen=self.length)
                self.version += 1
        with self._lock:
            rows = list(self._rows)
        excluded = self.files.excluded
        return [e for e in rows if e.name not in excluded] if excluded else rows


def pace_process() -> None:
    """Make this process fit to send events on time (`miro log play`, the window): the
    interpreter handed between threads within 0.1 ms, not Python's default 5 ms. (Freezing the
    long-lived objects out of the garbage collector, against its rare full collections of 10
    to 20 ms, made replays later, not earlier, in 10 of 12 paired runs: bench/README.md.)"""
    sys.setswitchinterval(SWITCH_INTERVAL)


def _spin(seconds: float) -> None:
    """Return after `seconds` (a fraction of a millisecond), without sleeping."""
    until = time.monotonic() + seconds
    while time.monotonic() < until:
        pass


def _check_length(length: int) -> int:
    if not 1 <= length <= MAX_HISTORY:
        raise ValueError(f"a history holds 1 to {MAX_HISTORY} events")
    return length


class Player:
    """Plays `files` into `send(event)`; see the module's doc. Starts paused at the start of
    the cut: call `start()` (the thread), then `play()`."""

    def __init__(
        self,
        files: FileSet,
        send: Callable[[Event], object],
        publish_clock: Callable[[ClockState], object] | None = None,
        *,
        rate: float = 1.0,
        loop: bool = False,
        history: int = DEFAULT_HISTORY,
    ) -> None:
        if not rate > 0:
            raise ValueError("the rate must be more than 0")
        self.files = files
        self.send = send
        self.publish_clock = publish_clock
        self.loop = loop
        self.history = EventHistory(files, history)
        self.latest: dict[TopicName, Event] = {}  # the last event sent of each topic
        self.sent = 0
        self.error: LogError | None = None  # why playing stopped (a damaged chunk)
        self.ended = threading.Event()  # set at the end of the cut (not looping)
        self._cond = threading.Condition()
        self._rate = rate
        self._playing = False
        self._steps: deque[int] = deque()  # next() (+1) and prev() (-1) waiting for the thread
        self._closed = False
        self._gen = 0  # bumped to make the thread read again from the position
        self._epoch = 0
        self._at_end = False
        self._fresh = True  # the first event played after a start or a jump sets the pace
        start = files.cut[0]
        self._pos: Key = at_time(start)
        self._shown: Key | None = None  # the event just behind the position, if it was sent
        self._anchor_log = start
        self._anchor_wall = time.monotonic()
        self._clock_sent = 0.0
        self._thread: threading.Thread | None = None
        self.held_back = 0  # times the clock waited for a send (eventlog.replay's credits)
        self._held_at = -HELD_SHOWN
        self._paces: deque[tuple[float, int]] = deque(maxlen=64)  # (wall, log) while held
        files.listeners.append(self._files_changed)

    # ---- state ----------------------------------------------------------------------------------

    @property
    def playing(self) -> bool:
        return self._playing

    @property
    def paused(self) -> bool:
        return not self._playing

    @property
    def rate(self) -> float:
        return self._rate

    @property
    def at_end(self) -> bool:
        return self._at_end

    @property
    def position(self) -> Key:
        return self._pos

    @property
    def held(self) -> bool:
        """Whether sending held the clock back within the last HELD_SHOWN seconds (a keep-all
        consumer slower than the rate): it plays slower than `rate` then (`pace`)."""
        return time.monotonic() - self._held_at < HELD_SHOWN

    def pace(self) -> float | None:
        """While `held`: the log seconds played per second over the last second or so (what the
        rate really is); None otherwise."""
        if not self.held:
            return None
        with self._cond:
            now = time.monotonic()
            marks = [m for m in self._paces if now - m[0] <= HELD_SHOWN]
            log_now = self._now()
        if not marks or now - marks[0][0] < 0.05:
            return None
        return max(0.0, (log_now - marks[0][1]) / 1e9 / (now - marks[0][0]))

    def log_now(self) -> int:
        """The log clock now, ns."""
        with self._cond:
            return self._now()

    def _now(self) -> int:
        if not self._playing:
            return self._anchor_log
        return self._anchor_log + int((time.monotonic() - self._anchor_wall) * self._rate * 1e9)

    def clock(self) -> ClockState:
        with self._cond:
            return ClockState(self._now(), self._rate, not self._playing, self._epoch)

    def _rebase(self, log_ns: int) -> None:
        self._anchor_log = log_ns
        self._anchor_wall = time.monotonic()

    def _jump(self, log_ns: int, pos: Key) -> None:
        """Move clock and position (under the lock): the thread reads again from `pos`."""
        self._rebase(log_ns)
        self._pos = pos
        self._shown = None
        self._at_end = False
        self._fresh = True
        self.error = None
        self.ended.clear()
        self._epoch += 1
        self._gen += 1
        self.history.restart(pos)
        self._cond.notify_all()

    # ---- commands (any thread) ------------------------------------------------------------------

    def play(self) -> None:
        with self._cond:
            if self._at_end:  # again from the start of the cut
                start = self.files.cut[0]
                self._jump(start, at_time(start))
            if not self._playing:
                self._rebase(self._anchor_log)
                self._playing = True
                self._fresh = True
                self._steps.clear()
                self._cond.notify_all()
        self._publish()

    def pause(self) -> None:
        with self._cond:
            if self._playing:
                self._rebase(self._now())
                self._playing = False
                self._cond.notify_all()
        self._publish()

    def toggle(self) -> None:
        if self._playing:
            self.pause()
        else:
            self.play()

    def stop(self) -> None:
        """Pause and go back to the start of the cut (Miro's Stop)."""
        with self._cond:
            self._playing = False
            self._steps.clear()
            start = self.files.cut[0]
            self._jump(start, at_time(start))
        self._publish()

    def seek(self, log_ns: int) -> None:
        """Move to log time `log_ns` (kept inside the cut), playing on if playing."""
        start, end = self.files.cut
        log_ns = min(max(log_ns, start), end)
        with self._cond:
            self._steps.clear()
            self._jump(log_ns, at_time(log_ns))
        self._publish()

    def seek_to(self, event: Event | Row) -> None:
        """Move to just before `event` (an event list's row): it is the next one played."""
        with self._cond:
            self._steps.clear()
            self._jump(event.log_time, event.key)
        self._publish()

    def set_rate(self, rate: float) -> None:
        if not rate > 0:
            raise ValueError("the rate must be more than 0")
        with self._cond:
            self._rebase(self._now())
            self._rate = rate
            self._cond.notify_all()
        self._publish()

    def faster(self, steps: int = 1) -> float:
        """Move the speed `steps` notches up (down when negative) on RATES; the new rate."""
        rate = self._rate
        if steps > 0:
            rate = next((r for r in RATES if r > rate * 1.0001), RATES[-1])
        elif steps < 0:
            rate = next((r for r in reversed(RATES) if r < rate / 1.0001), RATES[0])
        self.set_rate(rate)
        return rate

    def skip(self, direction: int) -> None:
        """Seek a 20th of the cut forward (`direction` > 0) or back."""
        start, end = self.files.cut
        step = max(int((end - start) * SKIP), 1_000_000)
        self.seek(self.log_now() + (step if direction > 0 else -step))

    def next(self) -> None:
        """Pause, then send the next event (Miro's Next)."""
        self.pause()
        with self._cond:
            self._steps.append(1)
            self._cond.notify_all()

    def prev(self) -> None:
        """Pause, then send the event before the one last sent (Miro's Prev)."""
        self.pause()
        with self._cond:
            self._steps.append(-1)
            self._cond.notify_all()

    def _files_changed(self, what: str) -> None:
        if what == "excluded":
            with self._cond:
                self._cond.notify_all()
                self.history.version += 1
            return
        start, end = self.files.cut
        with self._cond:
            now = self._now()
            if not start <= now <= end or (what == "files" and self.sent == 0):
                self._jump(start, at_time(start))
            else:  # the same place, read again (the files changed under it)
                self._rebase(now)
                self._gen += 1
                self._cond.notify_all()
        self._publish()

    def _publish(self) -> None:
        if self.publish_clock is not None:
            self.publish_clock(self.clock())
            self._clock_sent = time.monotonic()

    # ---- the thread -----------------------------------------------------------------------------

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="miro-player", daemon=True)
            self._thread.start()
            self._publish()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the thread (and wait for it)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        with contextlib.suppress(ValueError):
            self.files.listeners.remove(self._files_changed)

    def _run(self) -> None:
        while True:
            with self._cond:
                if self._closed:
                    return
            try:
                while self._step_back():
                    pass
                with self._cond:
                    gen, pos = self._gen, self._pos
                end = self.files.cut[1]
                outcome = _RESTART
                for event in self.files.forward(pos, end):
                    outcome = self._wait_for(event, gen)
                    if outcome == _SEND:
                        self._deliver(event)
                    elif outcome != _SKIP:
                        break
                else:
                    outcome = self._end(gen)
                if outcome == _CLOSED:
                    return
            except LogError as e:
                self._failed(e)
            except Exception as e:  # a defect: said with its traceback, and the player stops
                # there (ended, with the error) instead of its thread dying with `ended` unset
                logger().exception("the log player stopped on an internal error")
                self._failed(LogError(f"internal error: {e!r}"))

    def _wait_for(self, event: Event, gen: int) -> int:
        """Under the lock: wait until `event` is due (or a step allows it); what to do."""
        with self._cond:
            if self._at_end:  # the files changed: there is more to play after all
                self._at_end = False
                self.ended.clear()
            while True:
                if self._closed:
                    return _CLOSED
                if self._gen != gen:
                    return _RESTART
                if self.files.is_excluded(event.topic):
                    self._pos = after(event.key)
                    return _SKIP
                if self._playing:
                    if self._fresh and self._now() > event.log_time:
                        # Reading the first events after a start or a seek took time: play
                        # from them on time, not in a rush to catch up (and followers wait).
                        self._rebase(event.log_time)
                        self._clock_sent = 0.0
                    self._fresh = False
                    ahead = event.log_time - self._now()
                    if ahead <= 0:
                        self._take(event)
                        return _SEND
                    wait = ahead / 1e9 / self._rate
                    if wait <= SPIN:  # the last fraction of a millisecond: spin, lock free
                        self._cond.release()
                        try:
                            _spin(wait)
                        finally:
                            self._cond.acquire()
                        continue
                    wait = min(wait - SPIN, MAX_WAIT)
                elif self._steps and self._steps[0] < 0:
                    return _RESTART  # a step back: the thread reads from the new position
                elif self._steps:
                    self._steps.popleft()
                    self._rebase(max(event.log_time, self._anchor_log))
                    self._take(event)
                    self._clock_sent = 0.0  # followers move to this event's time
                    return _SEND
                else:
                    wait = MAX_WAIT
                if time.monotonic() - self._clock_sent >= CLOCK_PERIOD:
                    self._cond.release()
                    try:
                        self._publish()
                    finally:
                        self._cond.acquire()
                    continue
                self._cond.wait(wait)

    def _take(self, event: Event) -> None:
        """Under the lock: `event` is the next one sent; the position moves past it, and it is
        counted now, not once its send returns, so that what a pause() leaves counted is what
        goes out (the send of an event taken before the pause ends after it)."""
        self._pos = after(event.key)
        self._shown = event.key
        self.sent += 1

    def _deliver(self, event: Event) -> None:
        self.send(event)
        self.latest[event.name] = event
        self.history.append(event)
        held = self._hold(event)
        if held or self._clock_sent == 0.0:
            self._publish()

    def _hold(self, event: Event) -> bool:
        """If `event` left more than HELD s late (the send held the thread): the clock waits
        for it (set back to its log time); whether it did."""
        with self._cond:
            if not self._playing or self._now() - event.log_time <= HELD * self._rate * 1e9:
                return False
            self._rebase(event.log_time)
            now = time.monotonic()
            if now - self._held_at >= HELD_SHOWN:
                self._paces.clear()
            self._held_at = now
            self._paces.append((now, event.log_time))
            self.held_back += 1
            return True

    def _step_back(self) -> bool:
        """If a step back is the next command: send the event before the one last sent, the
        position moving to just after it; whether there was one."""
        with self._cond:
            if not self._steps or self._steps[0] > 0:
                return False
            self._steps.popleft()
            pos, shown = self._pos, self._shown
        start = self.files.cut[0]
        earlier = (
            e for e in self.files.backward(pos, start) if not self.files.is_excluded(e.topic)
        )
        target = next(earlier, None)
        if target is not None and target.key == shown:
            target = next(earlier, None)
        with self._cond:
            if target is None:  # at the start of the cut
                self._jump(start, at_time(start))
                return True
            self._jump(target.log_time, after(target.key))
            self._take(target)
        self._deliver(target)
        self._publish()
        return True

    def _end(self, gen: int) -> int:
        """At the end of the cut: loop, or pause there until something moves the position."""
        with self._cond:
            if self._gen != gen or self._closed:
                return _CLOSED if self._closed else _RESTART
            if self.loop and self._playing and self.sent:
                start = self.files.cut[0]
                self._jump(start, at_time(start))
                return _RESTART
            self._rebase(min(self._now(), self.files.cut[1]))
            self._playing = False
            self._at_end = True
            self.ended.set()
        self._publish()
        with self._cond:
            while not self._closed and self._gen == gen:
                if self._steps and self._steps[0] < 0:
                    break
                if self._steps:  # a step forward at the end: nothing to send
                    self._steps.popleft()
                    continue
                self._cond.wait(MAX_WAIT * 5)
            return _CLOSED if self._closed else _RESTART

    def _failed(self, why: LogError) -> None:
        """A damaged segment: stop there (paused), say why, until the position moves."""
        with self._cond:
            self.error = why
            self._playing = False
            gen = self._gen
            self.ended.set()
        self._publish()
        with self._cond:
            while not self._closed and self._gen == gen:
                self._cond.wait(MAX_WAIT * 5)
