"""The event handler, the message and the consumer of the manual's device pattern."""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Protocol

from miro_gen.devices.framers import Framer
from miro_gen.log import logger

_log = logger("MIRO")


@dataclass(frozen=True, slots=True)
class DevMessage:
    """One message from a device: its bytes and when they arrived (seconds since the epoch)."""

    data: bytes
    stamp: float


class DevConsumer(ABC):
    """Turns device messages into IDL types (and usually hands them to an Implementation's
    `integrate_data`). Runs on the reactor thread: it must not block."""

    @abstractmethod
    def handle_message(self, message: DevMessage) -> None:
        """Process one message."""

    def connection_changed(self, connected: bool) -> None:  # noqa: B027 - optional hook
        """Told when the device comes and goes (override to reset state or report)."""


class DevEventHandler:
    """Receives what a Connection reads (`handle_input`), frames it with `framer` and dispatches
    each message to `consumer`. A consumer that raises is logged and counted (`failed`); the
    next message is handled as usual."""

    def __init__(self, framer: Framer, consumer: DevConsumer | None = None) -> None:
        self.framer = framer
        self.consumer = consumer
        self.messages = 0  # dispatched
        self.failed = 0  # messages the consumer raised on

    def handle_input(self, data: bytes, stamp: float | None = None) -> None:
        """Bytes read from the device at `stamp` (default: now)."""
        stamp = time.time() if stamp is None else stamp
        for frame in self.framer.feed(data):
            self.dispatch_message(DevMessage(frame, stamp))

    def dispatch_message(self, message: DevMessage) -> None:
        """Hand one message to the consumer."""
        self.messages += 1
        if self.consumer is None:
            return
        try:
            self.consumer.handle_message(message)
        except Exception:
            self.failed += 1
            _log.exception("the device consumer failed on %r", message.data[:80])

    def handle_connect(self) -> None:
        """The device is (again) connected: start framing afresh."""
        self.framer.reset()
        if self.consumer is not None:
            self.consumer.connection_changed(True)

    def handle_disconnect(self) -> None:
        """The device went away."""
        if self.consumer is not None:
            self.consumer.connection_changed(False)


class Publisher(Protocol):
    def has_subscribers(self, type_name: str) -> bool: ...


class SubscriberNotice:
    """Logs (at notice level) when the first consumer subscribes to a publisher's events and when
    the last one leaves: `check()` it from a reactor timer. `supplier` has `has_subscribers(type)`
    (a StructuredPushSupplier), or is None for a driver that only answers polls."""

    def __init__(self, supplier: Publisher | None, type_name: str, what: str = "events") -> None:
        self.supplier = supplier
        self.type_name = type_name
        self.what = what
        self.subscribed = False

    def check(self) -> None:
        if self.supplier is None:
            return
        subscribed = self.supplier.has_subscribers(self.type_name)
        if subscribed != self.subscribed:
            self.subscribed = subscribed
            who = "someone" if subscribed else "nobody"
            _log.notice("%s subscribes to the %s (%s)", who, self.what, self.type_name)
