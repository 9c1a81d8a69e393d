"""Miro's LogNotify: record the events of a channel into an MCAP log.

Everything happens on the recorder's reactor thread: a raw tap hands over each frame's events,
the writer appends them to the current chunk, and a timer closes chunks that are a second old
and refreshes the progress line. The reactor stops on SIGINT, SIGTERM or SIGHUP, after `count`
events or `duration` seconds when given, and the file is then finished whatever the way out.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Sequence

from miro_gen.eventlog.progress import StatusLine, human_bytes
from miro_gen.eventlog.tap import RawEventTap
from miro_gen.eventlog.writer import LogWriter
from miro_gen.runtime import registry
from miro_gen.service.log_clock import CLOCK_TYPE  # a player's clock: never recorded
from miro_gen.service.server import Server
from miro_gen.transport.events.channels import EventChannel
from miro_gen.transport.events.frames import RawEvent

TICK = 0.25  # seconds between chunk checks and progress updates


class Recorder:
    """Records `subscriptions` of `channel` (resolved by `server`) into `writer`."""

    def __init__(
        self,
        server: Server,
        channel: EventChannel,
        subscriptions: Sequence[tuple[str, str]],
        writer: LogWriter,
        status: StatusLine,
        *,
        count: int = 0,
        duration: float = 0.0,
    ) -> None:
        self.server = server
        self.count = count  # events to record, then stop (0: no limit)
        self.writer = writer
        self.status = status
        self.started = time.monotonic()
        self._last = (self.started, 0)
        self.rate = 0.0
        registry.discover()  # now, not on the first event: that would delay it
        self.tap = RawEventTap(channel, subscriptions, self._write, skip=[CLOCK_TYPE])
        reactor = server.reactor()
        reactor.schedule_timer(TICK, TICK, self._tick)
        if duration > 0:
            reactor.schedule_timer(duration, 0, lambda _=None: self._stop())

    def _write(self, events: list[RawEvent], received_ns: int) -> None:
        if self.count:
            left = self.count - self.writer.messages
            if left <= 0:
                return  # the last frame's remainder, after the count was reached
            if len(events) >= left:
                self.writer.write(events[:left], received_ns)
                self._stop()
                return
        self.writer.write(events, received_ns)

    def _stop(self) -> None:
        self.server.shutdown()

    def _tick(self, _: object = None) -> None:
        self.writer.tick()
        now = time.monotonic()
        then, count = self._last
        if now - then >= 1.0:
            self.rate = (self.writer.messages - count) / (now - then)
            self._last = (now, self.writer.messages)
        self.status.update(self.line())

    def line(self) -> str:
        missed = f", {self.tap.missed} missed" if self.tap.missed else ""
        if self.writer.refused:
            missed += f", {self.writer.refused} refused (too many topics)"
        return (
            f"recording {self.writer.path}: {self.writer.messages} events{missed}, "
            f"{self.rate:.0f}/s, {human_bytes(self.writer.size())}"
        )

    def run(self) -> None:
        """Record until a signal, the count or the duration (or `server.shutdown()`); the
        file is finished after."""
        old = signal.signal(signal.SIGHUP, lambda *_: self.server.shutdown())
        try:
            self.server.run()
        finally:
            signal.signal(signal.SIGHUP, old)
            self.writer.finish()
