"""Event topics as Foxglove channels: one channel per offered (domain, type), its `omgidl`
schema the payload type's data schema, its messages the events' CDR payloads as they travel.

A topic is fed only while a Foxglove client subscribes to it: the first subscription opens a
raw tap on the event channel (the payloads are never decoded), the last one closes it, so an
unwatched camera costs the bridge nothing. Each tap's ZeroMQ queue is bounded (`TAP_BYTES`),
and the Foxglove server keeps at most `backlog` messages per client (oldest dropped first):
a slow client loses frames, never makes the bridge buffer without bound.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import foxglove

from miro_gen import clock
from miro_gen.eventlog.tap import PayloadTap
from miro_gen.eventlog.types import topic_name
from miro_gen.log import logger
from miro_gen.transport.events import EventChannel

_log = logger("MIRO")
TAP_BYTES = 64 << 20  # what a topic's tap may queue in ZeroMQ before frames are dropped
MESSAGE_ENCODING = "cdr"
SCHEMA_ENCODING = "omgidl"


@dataclass(frozen=True)
class Topic:
    """An offered event topic: what a Foxglove channel is made of."""

    domain: str
    type_name: str
    payload: str  # the payload's scoped IDL name (Miro::ExampleEventIDL): the schema's name
    type_hash: str

    @property
    def name(self) -> str:
        return topic_name(self.domain, self.type_name)


@dataclass
class _Advertised:
    topic: Topic
    channel: foxglove.Channel
    subscribers: set[int] = field(default_factory=set)
    tap: PayloadTap | None = None


class Topics:
    """The Foxglove channels of one event channel's topics. `update` (from the discovery
    thread) advertises new topics and removes gone ones; `subscribe`/`unsubscribe` (from the
    Foxglove server's threads) open and close taps on the reactor."""

    def __init__(
        self,
        channel: EventChannel,
        context: foxglove.Context,
        schema_of: Callable[[Topic], str | None],
    ) -> None:
        self.channel = channel
        self.reactor = channel.reactor
        self.context = context
        self.schema_of = schema_of
        self._lock = threading.Lock()
        self._by_topic: dict[str, _Advertised] = {}
        self._by_id: dict[int, _Advertised] = {}
        self.forwarded = 0

    def update(self, offered: list[Topic]) -> None:
        """Advertise the topics of `offered` not advertised yet; remove the others."""
        wanted: dict[str, Topic] = {}
        for t in offered:
            wanted.setdefault(t.name, t)  # one type per topic: the first offer's
        with self._lock:
            gone = [a for name, a in self._by_topic.items() if wanted.get(name) != a.topic]
        for a in gone:
            self._remove(a)
        for name, t in sorted(wanted.items()):
            with self._lock:
                if name in self._by_topic:
                    continue
            schema = self.schema_of(t)
            if schema is None:
                continue  # its service did not give the schema: tried again next time
            channel = foxglove.Channel(
                name,
                message_encoding=MESSAGE_ENCODING,
                schema=foxglove.Schema(
                    name=t.payload, encoding=SCHEMA_ENCODING, data=schema.encode()
                ),
                context=self.context,
                metadata={"domain": t.domain, "type_name": t.type_name, "type_hash": t.type_hash},
            )
            a = _Advertised(t, channel)
            with self._lock:
                self._by_topic[name] = a
                self._by_id[channel.id()] = a
            _log.info("foxglove: advertised %s (%s)", name, t.payload)

    def _remove(self, a: _Advertised) -> None:
        with self._lock:
            self._by_topic.pop(a.topic.name, None)
            self._by_id.pop(a.channel.id(), None)
            a.subscribers.clear()
        self.reactor.call_soon(self._close_tap, a)
        a.channel.close()
        _log.info("foxglove: %s is no longer offered", a.topic.name)

    def topic(self, name: str) -> Topic | None:
        with self._lock:
            a = self._by_topic.get(name)
        return None if a is None else a.topic

    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._by_topic)

    # ---- subscriptions (Foxglove server threads) -----------------------------------------------

    def subscribe(self, client: int, channel_id: int) -> None:
        with self._lock:
            a = self._by_id.get(channel_id)
            if a is None:
                return
            first = not a.subscribers
            a.subscribers.add(client)
        _log.debug("foxglove: client %d subscribes to %s", client, a.topic.name)
        if first:
            self.reactor.call_soon(self._open_tap, a)

    def unsubscribe(self, client: int, channel_id: int) -> None:
        with self._lock:
            a = self._by_id.get(channel_id)
            if a is None:
                return
            a.subscribers.discard(client)
            last = not a.subscribers
        _log.debug("foxglove: client %d unsubscribes from %s", client, a.topic.name)
        if last:
            self.reactor.call_soon(self._close_tap, a)

    # ---- the reactor thread ---------------------------------------------------------------------

    def _open_tap(self, a: _Advertised) -> None:
        with self._lock:
            if a.tap is not None or not a.subscribers or self._by_id.get(a.channel.id()) is not a:
                return
        t = a.topic
        raw_hash = bytes.fromhex(t.type_hash)
        # The SDK's own BaseChannel when there is one: the wrapper's checks cost as much as
        # the log itself, for each small event.
        base = getattr(a.channel, "base", None)
        log = base.log if base is not None else lambda data, at, _: a.channel.log(data, log_time=at)
        now = clock.current().time_ns

        def forward(payloads: Sequence[bytes], frame_hash: bytes, received_ns: int) -> None:
            if frame_hash != raw_hash:
                return  # another type under the same name: not this channel's schema
            at = now()  # the player's time under --clock log
            for data in payloads:  # the CDR payloads as received
                log(data, at, None)
            self.forwarded += len(payloads)

        a.tap = PayloadTap(self.channel, (t.domain, t.type_name), forward, queue_bytes=TAP_BYTES)
        _log.debug("foxglove: reading %s from %s", t.name, self.channel.name)

    def _close_tap(self, a: _Advertised) -> None:
        with self._lock:
            if a.tap is None or (a.subscribers and self._by_id.get(a.channel.id()) is a):
                return
            tap, a.tap = a.tap, None
        tap.close()

    def close(self) -> None:
        """Remove every channel (on the reactor thread, or after it stopped)."""
        with self._lock:
            advertised = list(self._by_topic.values())
            self._by_topic.clear()
            self._by_id.clear()
        for a in advertised:
            if a.tap is not None:
                a.tap.close()
                a.tap = None
            a.channel.close()


def topics_of(offers: list[Any], channel_name: str) -> list[Topic]:
    """The topics of `offers` (MiroService.Offer) on the event channel `channel_name`."""
    found = {
        Topic(o.domain, o.type_name, o.payload, o.type_hash)
        for o in offers
        if o.channel == channel_name and o.type_hash
    }
    return sorted(found, key=lambda t: (t.domain, t.type_name, t.type_hash))
