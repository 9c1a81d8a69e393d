"""QtEventBridge: the process's reactor in a background thread, its events on the GUI thread.

The manual's recipe (§11: detach the consumer into a thread, copy the event, post it to Qt,
and use a timer if events come faster than Qt can draw) done once. Each subscription has its
own consumer, which decodes every event afresh from the wire: the payload a slot receives is
that subscription's own copy, which the reactor thread never touches again. Events wait for
the GUI in a small buffer, latest-only per topic or a bounded queue, and at most one wake-up
per subscription is ever pending in Qt's event queue, so a flood of events costs the GUI
thread one delivery per repaint interval, not one per event.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Hashable, Iterable
from typing import Any

import shiboken6
from PySide6.QtCore import QCoreApplication, QEvent, QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import QWidget

from miro_gen.log import logger
from miro_gen.service.server import Server
from miro_gen.transport.events import (
    KEEP_ALL,
    EventChannel,
    StructuredEvent,
    StructuredPushConsumer,
)
from miro_gen.transport.reactor import Reactor

_log = logger("QT")
STOP_TIMEOUT = 5.0  # seconds stop() waits for the reactor thread
DEFAULT_RATE = 50.0  # deliveries a second, at most, per subscription


class Mailbox(QObject):
    """Items handed over by any thread with `offer()`, emitted on the GUI thread by `received`.

    With `queue=None` only the latest item of each key (an event's topic, domain and type)
    waits for the GUI; with `queue=N` up to N items wait in order and the oldest give way.
    Waiting items are delivered together, at most `max_rate` times a second (0: as fast as the
    GUI takes them). `deliveries` counts the turns of the GUI thread that delivered items,
    `delivered` the items, `dropped` those that never reached the GUI. Create it on the GUI
    thread (`QtEventBridge.mailbox()`); a consumer of your own may feed it."""

    received = Signal(object)
    _wake = Signal()

    def __init__(
        self,
        queue: int | None = None,
        max_rate: float = DEFAULT_RATE,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        if queue is not None and queue < 1:
            raise ValueError("a queue holds at least 1 item (queue=None: the latest only)")
        if not max_rate >= 0:
            raise ValueError("max_rate is deliveries a second: 0 (no limit) or more")
        self.queue = queue
        self.interval = 1.0 / max_rate if max_rate > 0 else 0.0
        self.delivered = 0
        self.deliveries = 0
        self.dropped = 0
        self._lock = threading.Lock()
        self._latest: dict[Hashable, Any] = {}
        self._fifo: deque[Any] = deque()
        self._wake_pending = False
        self._closed = False
        self._last_delivery = -math.inf
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(self._deliver)
        self._wake.connect(self._drain, Qt.ConnectionType.QueuedConnection)

    def offer(self, item: Any, key: Hashable = None) -> None:
        """Keep `item` for the GUI (from any thread) and wake the GUI unless a wake-up is
        already pending. Latest-only, an item replaces the waiting one of the same `key`
        (default: an event's (domain, type); else all items share one)."""
        if key is None and isinstance(item, StructuredEvent):
            key = (item.domain_name, item.type_name)
        with self._lock:
            if self._closed:
                return
            if self.queue is None:
                if key in self._latest:
                    self.dropped += 1
                self._latest[key] = item
            else:
                if len(self._fifo) >= self.queue:
                    self._fifo.popleft()
                    self.dropped += 1
                self._fifo.append(item)
            if self._wake_pending:
                return
            self._wake_pending = True
        self._wake.emit()

    def _drain(self) -> None:
        """GUI thread: deliver now, or when the rate allows."""
        if self._closed:
            return
        wait = self._last_delivery + self.interval - time.monotonic()
        if wait > 0:
            if not self._timer.isActive():
                self._timer.start(math.ceil(wait * 1000))
            return
        self._deliver()

    def _deliver(self) -> None:
        with self._lock:
            if self.queue is None:
                items = list(self._latest.values())
                self._latest.clear()
            else:
                items = list(self._fifo)
                self._fifo.clear()
            self._wake_pending = False
        self._last_delivery = time.monotonic()
        self.deliveries += 1
        for item in items:
            if self._closed:
                break
            self.delivered += 1
            self.received.emit(item)

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Take no more items; those still waiting are discarded."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._latest.clear()
            self._fifo.clear()
        self._timer.stop()


class _Consumer(StructuredPushConsumer):
    """Hands each event, on the reactor thread, to its subscription."""

    def __init__(self, channel: EventChannel, mailbox: Mailbox) -> None:
        super().__init__(channel, depth=KEEP_ALL)  # the mailbox keeps what the GUI gets
        self._mailbox = mailbox

    def push_structured_event(self, event: StructuredEvent) -> None:
        self._mailbox.offer(event)


class Subscription(Mailbox):
    """The events of some (domain, type) pairs, emitted on the GUI thread by `received` (a
    StructuredEvent), latest-only per topic or queued as for any `Mailbox`. Its consumer is
    its own (`consumer.missed` counts the events lost on the way from the supplier)."""

    def __init__(
        self,
        channel: EventChannel,
        subscriptions: Iterable[tuple[str, str]],
        queue: int | None = None,
        max_rate: float = DEFAULT_RATE,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(queue, max_rate, parent)
        self.consumer = _Consumer(channel, self)
        self.consumer.set_subscriptions(subscriptions)

    def close(self) -> None:
        """Stop receiving; events still waiting are discarded."""
        if not self.closed:
            super().close()
            self.consumer.close()


class QtEventBridge(QObject):
    """Runs a Server's (or a bare Reactor's) loop in a background thread for a Qt GUI, and
    hands its events to the GUI thread through `Subscription`s. Stops when `stop()` is
    called, when the application quits, or when the `window` it watches closes. A Server
    closes its sockets when its loop ends; a bare Reactor is left for its owner to close."""

    stopped = Signal()

    def __init__(
        self,
        server: Server | Reactor,
        *,
        window: QWidget | None = None,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.server = server
        self.reactor = server.reactor() if isinstance(server, Server) else server
        self.subscriptions: list[Mailbox] = []  # and mailboxes: what stop() closes
        self._thread: threading.Thread | None = None
        self._stopped = False
        self._windows: list[QWidget] = []
        app = QCoreApplication.instance()
        if app is not None:
            app.aboutToQuit.connect(self.stop)
        if window is not None:
            self.stop_with(window)

    # ---- subscriptions -------------------------------------------------------------------------

    def channel(self, name: str) -> EventChannel:
        """The event channel bound as `name` (raises MiroNaming.NotFound, SystemException)."""
        if not isinstance(self.server, Server):
            raise TypeError("a bridge over a bare Reactor has no naming service: pass channels")
        channel: EventChannel = self.server.resolve_channel(name)
        return channel

    def subscribe(
        self,
        subscriptions: Iterable[tuple[str, str]],
        channel: EventChannel | str = "EventChannel",
        *,
        queue: int | None = None,
        max_rate: float = DEFAULT_RATE,
    ) -> Subscription:
        """Events of these (domain, type) pairs (`*` for any) on `channel` (an EventChannel or
        the name it is bound as), delivered on the GUI thread; see `Subscription`."""
        if self._stopped:
            raise RuntimeError("this bridge is stopped")
        if isinstance(channel, str):
            channel = self.channel(channel)
        sub = Subscription(channel, subscriptions, queue, max_rate, self)
        self.subscriptions.append(sub)
        return sub

    def mailbox(self, queue: int | None = None, max_rate: float = DEFAULT_RATE) -> Mailbox:
        """A Mailbox that a consumer of your own (or any thread) feeds with `offer()`."""
        if self._stopped:
            raise RuntimeError("this bridge is stopped")
        box = Mailbox(queue, max_rate, self)
        self.subscriptions.append(box)
        return box

    # ---- the reactor thread --------------------------------------------------------------------

    def start(self) -> None:
        """Run the reactor in a background thread (once)."""
        if self._thread is not None or self._stopped:
            raise RuntimeError("a bridge starts once")
        self._thread = threading.Thread(target=self._run, name="miro-qt-reactor", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            if isinstance(self.server, Server):
                self.server.run()  # unbinds and closes its sockets when it returns
            else:
                self.reactor.run()
        except Exception:
            _log.exception("the reactor thread of the Qt bridge failed")

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stop(self, timeout: float = STOP_TIMEOUT) -> bool:
        """Close the subscriptions, stop the reactor and wait for its thread; whether it ended
        within `timeout` seconds. Safe to call again."""
        first = not self._stopped
        self._stopped = True
        for sub in self.subscriptions:
            sub.close()
        thread = self._thread
        if thread is None and first and isinstance(self.server, Server):
            # Never started: one turn of its loop, so that the Server unbinds and closes its
            # sockets as after any run (a ZeroMQ context with open sockets hangs at exit).
            self.reactor.call_soon(self.server.shutdown)
            self.server.run()
        if thread is not None and thread.is_alive():
            halt = self.server.shutdown if isinstance(self.server, Server) else self.reactor.stop
            halt()
            self.reactor.call_soon(halt)  # also if the loop had not begun yet (run() resets)
            thread.join(timeout)
            if thread.is_alive():
                _log.warning("the reactor thread did not stop within %g s", timeout)
                return False
        if first:
            self.stopped.emit()
        return True

    # ---- windows -------------------------------------------------------------------------------

    def stop_with(self, window: QWidget) -> None:
        """Stop when `window` closes (and stays closed: a close the window refuses does not)."""
        self._windows.append(window)
        window.installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        if event.type() == QEvent.Type.Close and watched in self._windows:
            QTimer.singleShot(0, self._window_closed)  # after the window has had its say
        return False

    def _window_closed(self) -> None:
        if not any(shiboken6.isValid(w) and w.isVisible() for w in self._windows):
            self.stop()
