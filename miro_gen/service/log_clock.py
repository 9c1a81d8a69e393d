"""`--clock log`: make a process's clock follow a log player's.

The player publishes `MiroLogClock` events (`MiroLog::Clock`) on its clock channel (`LogClock`
in its naming context). A follower resolves that channel, waiting for the player to bind it,
and hands every clock message to the process's `LogClock`, on the reactor thread. The server
starts it (service.server); the player (eventlog.player) publishes what it follows.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

import MiroLog
import MiroNaming

from miro_gen.clock import LogClock
from miro_gen.exceptions import SystemException
from miro_gen.log import logger
from miro_gen.transport.events.channels import EventChannel
from miro_gen.transport.events.consumer import StructuredPushConsumer
from miro_gen.transport.events.event import StructuredEvent

CLOCK_TYPE = "MiroLogClock"  # the type name of a player's clock events
RETRY = 0.2  # seconds between attempts to resolve the clock channel
_log = logger("MIRO")


class ClockServer(Protocol):
    """What a follower needs of its process's server (service.server.Server): its channels,
    and its clean-up, which stops the follower's thread."""

    def resolve_channel(self, name: str = ...) -> EventChannel: ...

    def on_shutdown(self, fn: Callable[[], object]) -> None: ...


class ClockFollower(StructuredPushConsumer):
    """Feeds a player's clock messages to `clock`."""

    def __init__(self, channel: EventChannel, clock: LogClock) -> None:
        super().__init__(channel, latest_only=True)  # only the newest clock state matters
        self.clock = clock
        self.set_subscriptions([("*", CLOCK_TYPE)])

    def push_structured_event(self, event: StructuredEvent) -> None:
        c = event.payload
        if isinstance(c, MiroLog.Clock):
            self.clock.update(c.log_time_ns, c.rate, c.paused, c.epoch)


def follow_log_clock(server: ClockServer, channel_name: str, clock: LogClock) -> threading.Thread:
    """Follow the clock published on `channel_name`, from a thread that waits for the channel
    to be bound (the process may start before the player)."""
    stop = threading.Event()
    server.on_shutdown(stop.set)

    def run() -> None:
        told = False
        while not stop.is_set():
            try:
                channel = server.resolve_channel(channel_name)
            except (MiroNaming.NotFound, SystemException) as e:
                if not told:
                    _log.notice("--clock log: waiting for %s (%s)", channel_name, e)
                    told = True
                stop.wait(RETRY)
                continue
            ClockFollower(channel, clock)
            _log.notice("--clock log: following the clock on %s", channel.name)
            return

    thread = threading.Thread(target=run, name="miro-log-clock", daemon=True)
    thread.start()
    return thread
