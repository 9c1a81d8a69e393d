"""A raw consumer of an event channel: events as they travel, payloads not decoded.

What the recorder and `miro hz` need: every event's bytes, stamps and sequence number, at the
rate the channel carries them, without the cost of decoding. Like the transport's consumers it
subscribes by (domain, type), `*` matching any, filters at the socket where a prefix can, and
counts the events it missed per supplier and type from their sequence numbers.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import zmq

from miro_gen.eventlog.types import matches
from miro_gen.log import PeerWarnings, logger
from miro_gen.transport import shm, sockets
from miro_gen.transport.events import EventChannel, subscription_prefix
from miro_gen.transport.events.channel_link import ChannelLink
from miro_gen.transport.events.frames import (
    FrameError,
    RawEvent,
    batch_payloads,
    parse_batch,
    split_topic,
)
from miro_gen.transport.events.frames import topic as topic_frame
from miro_gen.transport.events.gaps import GapCounter
from miro_gen.transport.events.links import SubscribingLink

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts
# A recorder would rather queue than drop while it writes a chunk: up to this many bytes of
# frames of the largest size (batched frames of small events count as frames too).
QUEUE_BYTES = 1 << 30
LINK_FRAMES = 100_000  # frames a backbone's link (Zenoh's) keeps waiting for the reactor

Handler = Callable[[list[RawEvent], int], object]  # events of one frame, receive time ns
# The payloads of one frame, its raw type hash, the receive time (PayloadTap).
PayloadHandler = Callable[[Sequence[bytes], bytes, int], object]
COPY_BELOW = 64 << 10  # frames smaller than this are copied whole before their payloads


class RawEventTap:
    """Calls `handler(events, received_ns)` on the reactor thread for each frame received
    whose topic matches `subscriptions`. `skip` type names are never delivered; what waits in
    ZeroMQ beyond `queue_bytes` (of frames of the largest size) is dropped."""

    def __init__(
        self,
        channel: EventChannel,
        subscriptions: Iterable[tuple[str, str]],
        handler: Handler,
        skip: Iterable[str] = (),
        queue_bytes: int = QUEUE_BYTES,
    ) -> None:
        self.channel = channel
        self.reactor = channel.reactor
        self.handler = handler
        self.filters = list(subscriptions)
        self.skip = set(skip)
        self.received = 0
        self.gaps = GapCounter()
        self.bad_frames = 0
        self._wanted: dict[bytes, bool] = {}
        self.sub: SubscribingLink | None = None
        if channel.links is not None:  # a backbone without channel hosts (Zenoh)
            self.sub = channel.subscribing(self._read_link, LINK_FRAMES)
            for prefix in {subscription_prefix(d, t) for d, t in self.filters}:
                self.sub.subscribe(prefix)
            return
        context = self.reactor.context
        self.socket: zmq.Socket[Any] = sockets.connecting_socket(context, zmq.SUB)
        self.socket.setsockopt(zmq.RCVHWM, sockets.queue_limit(context, queue_bytes))
        for prefix in {subscription_prefix(d, t) for d, t in self.filters}:
            self.socket.setsockopt(zmq.SUBSCRIBE, prefix)
            # It reads no shared memory: its suppliers send it large events in frames.
            self.socket.setsockopt(zmq.SUBSCRIBE, shm.framed_marker() + prefix)
        resolve = channel.resolve
        self.link = ChannelLink(  # found again when the channel's host restarts
            self.reactor,
            self.socket,
            # the in-process or ipc:// twin when there is one, as consumers connect
            channel.endpoints(context)[1],
            None if resolve is None else lambda: resolve().endpoints(context)[1],
            lambda up: None,
        )
        self.reactor.call_soon(self.reactor.register, self.socket, self._readable)

    COPY = True  # frames received as bytes (False: as zmq.Frame, whose buffer is read)

    def _readable(self) -> None:
        for _ in range(1000):
            try:
                parts = self.socket.recv_multipart(zmq.NOBLOCK, copy=self.COPY)
            except zmq.Again:
                return
            received_ns = time.time_ns()
            try:
                events = self._parse(parts)
            except FrameError as e:
                self.bad_frames += 1
                _peer_warnings.warning("dropped an event frame on %s: %s", self.channel.name, e)
                continue
            if events:
                self.received += len(events)
                self.handler(events, received_ns)

    def _read_link(self) -> None:
        assert self.sub is not None
        for _ in range(1000):
            try:
                frame = self.sub.receive()
            except ValueError as e:
                self.bad_frames += 1
                _peer_warnings.warning("dropped an event frame on %s: %s", self.channel.name, e)
                continue
            if frame is None:
                return
            self._deliver([frame[0], bytes(frame[1])], time.time_ns())
        self.reactor.call_soon(self._read_link)  # more may wait: next turn

    def _deliver(self, parts: list[bytes], received_ns: int) -> None:
        try:
            events = self._parse(parts)
        except FrameError as e:
            self.bad_frames += 1
            _peer_warnings.warning("dropped an event frame on %s: %s", self.channel.name, e)
            return
        if events:
            self.received += len(events)
            self.handler(events, received_ns)

    def _parse(self, parts: list[Any]) -> list[RawEvent]:
        if len(parts) != 2:
            raise FrameError(f"{len(parts)} frames, expected 2")
        head, body = parts
        wanted = self._wanted.get(head)
        domain, type_name = split_topic(head)
        if wanted is None:
            wanted = type_name not in self.skip and any(
                matches(f, domain, type_name) for f in self.filters
            )
            if len(self._wanted) < 10_000:
                self._wanted[head] = wanted
        if not wanted:
            return []
        events = parse_batch(domain, type_name, body)
        observe = self.gaps.observe
        for e in events:
            observe(e.supplier, type_name, e.seq)
        return events

    @property
    def missed(self) -> int:
        """Events lost between their suppliers and this tap."""
        return self.gaps.missed

    def close(self) -> None:
        if self.sub is not None:
            self.sub.close()
            return
        self.link.close_socket()


class PayloadTap(RawEventTap):
    """A tap of one (domain, type) that hands over only the payloads of each frame, with the
    frame's raw type hash: what a forwarder needs (the Foxglove bridge), at a fraction of the
    cost of a RawEvent and a sequence check per event."""

    def __init__(
        self,
        channel: EventChannel,
        topic: tuple[str, str],
        handler: PayloadHandler,
        queue_bytes: int = QUEUE_BYTES,
    ) -> None:
        self.forward = handler
        super().__init__(channel, [topic], self._handed, queue_bytes=queue_bytes)
        self._head = topic_frame(*topic)

    def _handed(self, events: list[RawEvent], received_ns: int) -> None:  # pragma: no cover
        raise AssertionError("PayloadTap hands over payloads (_parse)")

    COPY = False  # frames as zmq.Frame: large payloads are copied once, out of ZeroMQ's buffer

    def _parse(self, parts: list[Any]) -> list[RawEvent]:
        if len(parts) != 2:
            raise FrameError(f"{len(parts)} frames, expected 2")
        head, body = parts  # zmq.Frame from ZeroMQ's socket, bytes from a backbone's link
        if not isinstance(head, bytes):
            head = head.bytes
        if head != self._head:
            split_topic(head)  # a malformed one is a bad frame
            return []  # another topic under the subscribed prefix
        if not isinstance(body, bytes):
            # a batch of small events: one copy of the frame, whose slices are cheaper than
            # a view's; a large payload: read in place
            body = body.bytes if len(body) < COPY_BELOW else body.buffer
        raw_hash, payloads = batch_payloads(body)
        self.received += len(payloads)
        if payloads:
            self.forward(payloads, raw_hash, time.time_ns())
        return []
