"""Miro's LogPlayer: re-publish a log's events with their original spacing.

The player keeps a *log clock*: log time advances from an anchor at `rate` log seconds per
second, or stands still while paused. Each event is sent when the log clock reaches its log
time, through a `ReplaySupplier`, with its recorded domain, type, type hash, sequence number and
source stamp, so that consumers cannot tell replay from live. The clock itself is published, on
a channel of its own (`LogClock`: consumers of the robot's channel never see it), as
`MiroLogClock` events (`MiroLog::Clock`) whenever it changes and twice a second, so that
processes started with `--clock log` run on the replayed time (miro_gen.clock).

`pause()`, `resume()`, `step()` and `stop()` may be called from any thread (the key reader).
"""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from mcap.records import Message

from miro_gen.eventlog.reader import LogReader, Topic
from miro_gen.eventlog.replay import ReplaySupplier
from miro_gen.eventlog.types import matches
from miro_gen.service.log_clock import CLOCK_TYPE
from miro_gen.transport.events import StructuredPushSupplier

CLOCK_CHANNEL = "LogClock"
CLOCK_PERIOD = 0.5  # seconds between clock events while nothing changes


@dataclass
class PlayOptions:
    rate: float = 1.0
    loop: bool = False
    start: float = 0.0  # seconds from the log's first event
    end: float | None = None  # seconds from the log's first event; None: to the last
    topics: list[tuple[str, str]] | None = None  # (domain, type) patterns; None: all


class Player:
    """Plays `log` into `supplier`'s channel according to `options`."""

    def __init__(
        self,
        log: LogReader,
        supplier: ReplaySupplier,
        options: PlayOptions,
        clock_supplier: StructuredPushSupplier | None = None,
    ) -> None:
        if not options.rate > 0:
            raise ValueError("the rate must be more than 0")
        self.log = log
        self.supplier = supplier
        self.clock_supplier = clock_supplier
        self.options = options
        self.rate = options.rate
        self.sent = 0
        self.first_ns, self.last_ns = log.span()
        self.begin_ns = self.first_ns + int(options.start * 1e9)
        self.end_ns = None if options.end is None else self.first_ns + int(options.end * 1e9)
        self._cond = threading.Condition()
        self._paused = False
        self._steps = 0
        self._stopped = False
        self._epoch = 0
        self._wall_anchor = time.monotonic()
        self._log_anchor = self.begin_ns
        self._replay_ids: dict[int, int] = {}  # channel id -> the replayed supplier id
        self.on_progress: Callable[[Player], object] | None = None
        self._clock_sent = 0.0

    # ---- the clock ------------------------------------------------------------------------------

    def log_now(self) -> int:
        """The log clock now, ns."""
        with self._cond:
            return self._log_now_locked()

    def _log_now_locked(self) -> int:
        if self._paused:
            return self._log_anchor
        return self._log_anchor + int((time.monotonic() - self._wall_anchor) * self.rate * 1e9)

    def _rebase(self, log_ns: int) -> None:
        self._log_anchor = log_ns
        self._wall_anchor = time.monotonic()

    @property
    def paused(self) -> bool:
        return self._paused

    def pause(self) -> None:
        with self._cond:
            if not self._paused:
                self._rebase(self._log_now_locked())
                self._paused = True
                self._cond.notify_all()
        self.publish_clock()

    def resume(self) -> None:
        with self._cond:
            if self._paused:
                self._paused = False
                self._steps = 0
                self._rebase(self._log_anchor)
                self._cond.notify_all()
        self.publish_clock()

    def toggle(self) -> None:
        if self._paused:
            self.resume()
        else:
            self.pause()

    def step(self) -> None:
        """Pause if playing; then send the next event and move the log clock to it."""
        self.pause()
        with self._cond:
            self._steps += 1
            self._cond.notify_all()

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._cond.notify_all()

    def publish_clock(self) -> None:
        if self.clock_supplier is None:
            return
        import MiroLog

        with self._cond:
            clock = MiroLog.Clock(self._log_now_locked(), self.rate, self._paused, self._epoch)
        self.clock_supplier.push(CLOCK_TYPE, clock, stamp=clock.log_time_ns / 1e9)
        self._clock_sent = time.monotonic()

    # ---- playing --------------------------------------------------------------------------------

    def _messages(self) -> Iterator[tuple[Topic, Message]]:
        patterns = self.options.topics
        for topic, message in self.log.messages(start_ns=self.begin_ns, end_ns=self.end_ns):
            if patterns is None or any(matches(p, topic.domain, topic.type_name) for p in patterns):
                yield topic, message

    def _wait_until(self, log_ns: int) -> bool:
        """Wait until the log clock reaches `log_ns` (or a step allows the next event); False
        when stopped."""
        with self._cond:
            while not self._stopped:
                if self._paused:
                    if self._steps:
                        self._steps -= 1
                        self._rebase(max(log_ns, self._log_anchor))
                        return True
                    self._cond.release()
                    try:
                        self._tick()
                    finally:
                        self._cond.acquire()
                    self._cond.wait(0.1)
                    continue
                ahead = (log_ns - self._log_now_locked()) / 1e9 / self.rate
                if ahead <= 0:
                    return True
                self._cond.release()
                try:
                    self._tick()
                finally:
                    self._cond.acquire()
                self._cond.wait(min(ahead, 0.1))
            return False

    def _tick(self) -> None:
        if time.monotonic() - self._clock_sent >= CLOCK_PERIOD:
            self.publish_clock()
        if self.on_progress is not None:
            self.on_progress(self)

    def play(self) -> bool:
        """Play to the end (again and again with `loop`); False when stopped first."""
        while True:
            with self._cond:
                self._rebase(self.begin_ns)
            self.publish_clock()
            for topic, message in self._messages():
                if not self._wait_until(message.log_time):
                    return False
                self.supplier.push_encoded(
                    topic.domain,
                    topic.type_name,
                    topic.type_hash,
                    self._replay_id(topic),
                    message.sequence,
                    message.publish_time,
                    message.log_time,
                    message.data,
                )
                self.sent += 1
                if self._paused:  # a step: followers move to this event's time
                    self.publish_clock()
                if self.on_progress is not None and self.sent % 64 == 0:
                    self.on_progress(self)
            if not self.options.loop:
                break
            with self._cond:
                self._epoch += 1
        with self._cond:
            self._rebase(self._log_now_locked())
            self._paused = True
        self.publish_clock()  # followers stop at the end of the log
        return True

    def _replay_id(self, topic: Topic) -> int:
        """One supplier id per replayed channel, so consumers count its gaps as recorded."""
        sid = self._replay_ids.get(topic.id)
        if sid is None:
            sid = self._replay_ids[topic.id] = random.getrandbits(63)
        return sid
