"""A supplier's or consumer's connection to its event channel, and how it comes back.

A channel lives in the process that hosts it. When that process dies and another one hosts the
channel again, the new host binds new ports, so sockets that keep reconnecting to the old
endpoint would wait forever. A `ChannelLink` watches its socket's connection (a ZeroMQ socket
monitor, read on the reactor thread): while it is down, the process's `ChannelWatcher` thread
resolves the channel's name again a few times a second, and when the name is bound to another
endpoint, the link moves its socket there. Consumers' subscriptions and suppliers' knowledge of
them follow the new connection (ZeroMQ sends subscriptions again on every new connection).
"""

from __future__ import annotations

import contextlib
import threading
import weakref
from collections.abc import Callable
from typing import Any

import zmq

from miro_gen.log import logger
from miro_gen.transport import sockets
from miro_gen.transport.reactor import LockLike, Reactor

_log = logger("MIRO")

RESOLVE_EVERY = 0.25  # seconds between two look-ups of a channel whose connection is down
CLOSE_TIMEOUT = 10.0  # seconds a closing watcher waits for its look-up (naming calls: 5 s)
_EVENTS = zmq.EVENT_HANDSHAKE_SUCCEEDED | zmq.EVENT_DISCONNECTED


class ChannelLink:
    """Connects `socket` to `endpoint` and keeps it connected to wherever `resolve()` (None: the
    endpoint is fixed) says the channel is; `on_change(connected)` runs on the reactor thread
    whenever the connection comes up or goes down. A socket that other threads use too (a
    shared one, `Reactor.register_shared`) is moved and closed under its `lock`."""

    def __init__(
        self,
        reactor: Reactor,
        socket: zmq.Socket[Any],
        endpoint: str,
        resolve: Callable[[], str] | None,
        on_change: Callable[[bool], object],
        lock: LockLike | None = None,
    ) -> None:
        self.reactor = reactor
        self.socket = socket
        self.lock: LockLike = contextlib.nullcontext() if lock is None else lock
        self.endpoint = endpoint
        self.resolve = resolve
        self.on_change = on_change
        self.connected = False
        self.closed = False
        self.moves = 0  # times the channel was found at another endpoint
        self._monitor = sockets.monitor(socket, _EVENTS)
        socket.connect(endpoint)
        reactor.call_soon(reactor.register, self._monitor, self.read_events)
        if endpoint.startswith("inproc://"):  # the host's own process: no handshake, no loss
            self.connected = True
            reactor.call_soon(on_change, True)

    def read_events(self) -> None:
        while True:
            try:
                event, _ = sockets.monitor_event(self._monitor.recv_multipart(zmq.NOBLOCK))
            except zmq.Again:
                return
            except zmq.ZMQError:  # the monitor was closed
                return
            up = event == zmq.EVENT_HANDSHAKE_SUCCEEDED
            if up == self.connected:
                continue
            self.connected = up
            self.on_change(up)
            if not up and self.resolve is not None:
                watcher(self.reactor).watch(self)

    def move(self, endpoint: str) -> None:
        """Connect the socket to `endpoint` instead (reactor thread)."""
        if self.closed or self.connected or endpoint == self.endpoint:
            return
        with self.lock:
            with contextlib.suppress(zmq.ZMQError):
                self.socket.disconnect(self.endpoint)
            self.socket.connect(endpoint)
        _log.notice("event channel moved from %s to %s", self.endpoint, endpoint)
        self.endpoint = endpoint
        self.moves += 1

    def close_socket(self) -> None:
        """Stop watching and close the socket, on the reactor thread (from any thread)."""

        def close() -> None:
            self.reactor.unregister(self._monitor)
            with self.lock:
                self.closed = True
                with contextlib.suppress(zmq.ZMQError):
                    self.socket.disable_monitor()
                self._monitor.close(0)
                self.reactor.unregister(self.socket)
                self.socket.close(0)

        self.reactor.call_soon(close)


class ChannelWatcher:
    """The thread of a reactor that looks the channels of its disconnected links up again.
    It runs only while a link is down, and never on the reactor thread (a look-up blocks)."""

    def __init__(self, reactor: Reactor) -> None:
        self.reactor = reactor
        self._links: set[ChannelLink] = set()
        self._lock = threading.Condition()
        self._thread: threading.Thread | None = None
        self._closed = False

    def watch(self, link: ChannelLink) -> None:
        with self._lock:
            if self._closed:
                return
            self._links.add(link)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="miro-rematch", daemon=True)
                self._thread.start()

    def _run(self) -> None:
        while True:
            with self._lock:
                self._links = {k for k in self._links if not (k.connected or k.closed)}
                if not self._links or self.reactor.closed or self._closed:
                    self._thread = None
                    return
                links = list(self._links)
            for link in links:
                if link.resolve is None:
                    continue
                try:
                    endpoint = link.resolve()
                except Exception as e:  # not bound (yet), the naming service unreachable
                    _log.debug("looking the channel up again: %s", e)
                    continue
                if endpoint != link.endpoint:
                    self.reactor.call_soon(link.move, endpoint)
            with self._lock:
                if not self._closed:
                    self._lock.wait(RESOLVE_EVERY)

    def close(self, timeout: float = CLOSE_TIMEOUT) -> None:
        """Look nothing up any more, and wait for a look-up under way: it uses the process's
        invoker, whose sockets must not be closed under it (ZeroMQ aborts the process)."""
        with self._lock:
            self._closed = True
            self._lock.notify_all()
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)


_watchers: weakref.WeakKeyDictionary[Reactor, ChannelWatcher] = weakref.WeakKeyDictionary()
_watchers_lock = threading.Lock()


def close_watcher(reactor: Reactor) -> None:
    """Stop the channel watcher of `reactor`, if it has one (before its process's sockets
    are closed)."""
    with _watchers_lock:
        w = _watchers.pop(reactor, None)
    if w is not None:
        w.close()


def watcher(reactor: Reactor) -> ChannelWatcher:
    """The channel watcher of `reactor`."""
    with _watchers_lock:
        w = _watchers.get(reactor)
        if w is None:
            w = _watchers[reactor] = ChannelWatcher(reactor)
        return w
