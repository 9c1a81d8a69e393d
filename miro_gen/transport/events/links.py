"""A supplier's and a consumer's link to their event channel: what carries their frames and
subscriptions, the part of events a backbone provides (service.backbone).

A supplier hands its link one frame per topic and batch (`send`), and hears from it, on the
reactor thread, when the channel comes and goes and what consumers subscribe to; a consumer
tells its link what it subscribes to and takes frames from it when told they wait. Everything
else (batching, sequence numbers, a consumer's queue and gaps) is the same over any backbone,
and the frames are transport.events.frames'. A channel makes its suppliers' and consumers'
links (`EventChannel.publishing`, `EventChannel.subscribing`).

Over ZeroMQ a link is a socket made by transport.sockets and kept connected to the channel's
proxy wherever the channel moves (`ChannelLink`): the supplier's an XPUB socket (the proxy
forwards subscriptions to it), the consumer's a SUB socket. Their queues hold at most `hwm`
frames per peer, fewer when the largest message allowed is large (`sockets.queue_limit`).

A supplier's link is used on the reactor thread, which owns its socket. A *direct* one
(`direct=True`, a log player's: its events are due to the tenth of a millisecond, and a turn
of the reactor is a hand-off between threads that costs more) is sent from the thread that
calls `send`, the caller's own thread, without waiting for the reactor: its socket is shared
(`Reactor.register_shared`), used by one thread at a time under the link's lock; the reactor
still reads the subscriptions and watches the connection, and the callbacks still run there.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any, Protocol

import zmq

from miro_gen.transport import sockets
from miro_gen.transport.events.channel_link import ChannelLink
from miro_gen.transport.reactor import Reactor

_NOBLOCK = int(zmq.NOBLOCK)
KEEP_ALL_FRAMES = 512  # frames a keep-all consumer's socket queues, at least


class PublishingLink(Protocol):
    """What a supplier needs of its link to its channel."""

    @property
    def connected(self) -> bool: ...

    @property
    def moves(self) -> int:
        """Times the channel was found elsewhere (its host restarted)."""
        ...

    def send(self, topic: bytes, body: bytes, copy: bool) -> bool:
        """Send a topic and a batch frame without blocking (`copy`: False for a large body,
        which the link may then keep instead of copying); False when it cannot be sent now.
        On the reactor thread, or from any thread for a direct link."""
        ...

    def close(self) -> None: ...


class SubscribingLink(Protocol):
    """What a consumer needs of its link to its channel (on the reactor thread)."""

    @property
    def connected(self) -> bool: ...

    @property
    def moves(self) -> int: ...

    def subscribe(self, prefix: bytes) -> None:
        """Receive the frames whose topic starts with `prefix`."""
        ...

    def unsubscribe(self, prefix: bytes) -> None: ...

    def receive(self) -> tuple[bytes, memoryview] | None:
        """The next frame waiting, as (topic, batch) with the batch not copied; None when none
        waits. ValueError for a message that is not a topic and a batch (it is gone)."""
        ...

    def close(self) -> None: ...


class ZmqPublishing:
    """A supplier's XPUB socket connected to its channel's proxy at `endpoint` (found again with
    `find`, None for fixed endpoints). `on_connection(up)` and `on_subscriptions(changes)`,
    each change (subscribed, prefix), run on the reactor thread; a lost connection's
    unsubscriptions come after its `on_connection(False)`. At most `hwm` frames wait for the
    proxy, at least `burst` (a turn's events, however large the messages allowed). `direct`:
    `send` may be called from any thread, and sends at once (the module's doc)."""

    def __init__(
        self,
        reactor: Reactor,
        endpoint: str,
        find: Callable[[], str] | None,
        on_connection: Callable[[bool], object],
        on_subscriptions: Callable[[list[tuple[bool, bytes]]], object],
        hwm: int,
        burst: int,
        *,
        direct: bool = False,
    ) -> None:
        context = reactor.context
        self.socket = sockets.connecting_socket(context, zmq.XPUB)
        self.socket.setsockopt(zmq.SNDHWM, min(hwm, max(burst, sockets.queue_limit(context))))
        self.socket.setsockopt(zmq.XPUB_VERBOSER, 1)
        # At the high-water mark an XPUB drops silently; with NODROP a non-blocking send fails
        # instead, so that the supplier counts what it drops. It never blocks either way.
        self.socket.setsockopt(zmq.XPUB_NODROP, 1)
        # No queue for a connection that is down: the channel's subscriptions end with it, and
        # what is pushed meanwhile is counted as dropped, not sent into the void.
        self.socket.setsockopt(zmq.IMMEDIATE, 1)
        self._on_subscriptions = on_subscriptions
        self.reactor = reactor
        self.direct = direct
        self.lock = threading.Lock()  # used only by a direct link's (shared) socket
        self.link = ChannelLink(
            reactor, self.socket, endpoint, find, on_connection, self.lock if direct else None
        )
        if direct:
            reactor.call_soon(reactor.register_shared, self.socket, self.lock, self._readable)
        else:
            reactor.call_soon(reactor.register, self.socket, self._readable)

    @property
    def connected(self) -> bool:
        return self.link.connected

    @property
    def moves(self) -> int:
        return self.link.moves

    def send(self, topic: bytes, body: bytes, copy: bool) -> bool:
        if self.direct:
            return self._send_direct(topic, body, copy)
        try:
            self.socket.send_multipart([topic, body], _NOBLOCK, copy=copy)
        except zmq.Again:
            return False
        return True

    def _send_direct(self, topic: bytes, body: bytes, copy: bool) -> bool:
        """`send` of a direct link, on the caller's thread. The send may have taken the signal
        of subscriptions that came meanwhile (Reactor.register_shared): if they wait, the
        reactor reads them."""
        with self.lock:
            if self.link.closed:
                return False
            try:
                self.socket.send_multipart([topic, body], _NOBLOCK, copy=copy)
                sent = True
            except zmq.Again:
                sent = False
            except zmq.ZMQError:  # the context is ending: nobody to send to any more
                return False
            waiting = int(self.socket.getsockopt(zmq.EVENTS)) & zmq.POLLIN
        if waiting:
            self.reactor.call_soon(self._readable)
        return sent

    def _readable(self) -> None:
        # A lost connection's subscriptions end with unsubscriptions that ZeroMQ queues after
        # its monitor event: read that event first, so that the supplier hears of it first.
        self.link.read_events()
        changes = []
        with self.lock if self.direct else contextlib.nullcontext():
            if self.link.closed or self.socket.closed:
                return
            while True:
                try:
                    msg = self.socket.recv(_NOBLOCK)
                except zmq.Again:
                    # A direct link's ZMQ_FD signals once, and looking at ZMQ_EVENTS resets
                    # it: a subscription that came since the last receive would wait unseen
                    # (a player paused, or waiting for subscribers, sends nothing to find it).
                    if self.direct and int(self.socket.getsockopt(zmq.EVENTS)) & zmq.POLLIN:
                        continue
                    break
                if msg:
                    changes.append((msg[0] == 1, msg[1:]))
        if changes:
            self._on_subscriptions(changes)

    def close(self) -> None:
        self.link.close_socket()


class ZmqSubscribing:
    """A consumer's SUB socket connected to its channel's proxy at `endpoint` (found again with
    `find`, None for fixed endpoints); `on_readable()` runs on the reactor thread when frames
    wait. At most `hwm` frames wait per peer, fewer when the largest message allowed is large
    (`sockets.queue_limit`), except for a keep-all consumer (`keep_all`): it must not lose
    what it would keep while its process is not scheduled, so its queue is KEEP_ALL_FRAMES
    frames (128 MiB of full batches of small events; large events from this host are
    descriptors, from other hosts up to the largest message each)."""

    def __init__(
        self,
        reactor: Reactor,
        endpoint: str,
        find: Callable[[], str] | None,
        on_readable: Callable[[], object],
        hwm: int,
        keep_all: bool = False,
    ) -> None:
        context = reactor.context
        self.socket: zmq.Socket[Any] = sockets.connecting_socket(context, zmq.SUB)
        queue = sockets.queue_limit(context)
        limit = min(hwm, max(queue, KEEP_ALL_FRAMES)) if keep_all else min(hwm, queue)
        self.socket.setsockopt(zmq.RCVHWM, limit)
        if keep_all:  # and room in the kernel (bytes), as the channel's side has
            self.socket.setsockopt(zmq.RCVBUF, 4 << 20)
        self.link = ChannelLink(reactor, self.socket, endpoint, find, lambda up: None)
        self._recv = self.socket.recv_multipart
        reactor.call_soon(reactor.register, self.socket, on_readable)

    @property
    def connected(self) -> bool:
        return self.link.connected

    @property
    def moves(self) -> int:
        return self.link.moves

    def subscribe(self, prefix: bytes) -> None:
        self.socket.setsockopt(zmq.SUBSCRIBE, prefix)

    def unsubscribe(self, prefix: bytes) -> None:
        self.socket.setsockopt(zmq.UNSUBSCRIBE, prefix)

    def receive(self) -> tuple[bytes, memoryview] | None:
        try:
            parts = self._recv(_NOBLOCK, copy=False)  # large payloads are decoded in place
        except zmq.Again:
            return None
        if len(parts) != 2:
            raise ValueError(f"{len(parts)} frames, expected 2")
        return parts[0].bytes, parts[1].buffer

    def close(self) -> None:
        self.link.close_socket()
