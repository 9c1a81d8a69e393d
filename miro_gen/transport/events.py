"""Event channels: suppliers push typed events, any number of consumers receive those they
subscribe to (Miro's EventChannel, StructuredPushSupplier, StructuredPushConsumer).

A channel is a ZeroMQ XSUB/XPUB proxy, run by libzmq in a thread of the process that hosts it,
and bound in the naming service (transport.channels; docs/PROTOCOL.md, "Event channels").
Suppliers connect XPUB sockets to its XSUB side, so subscriptions travel back to them:
`has_subscribers()` tells a supplier whether anyone listens, and `push()` skips encoding when
nobody does. Consumers connect SUB sockets to its XPUB side.

Each event carries its domain (by convention the supplier's naming context: the robot), its type
name, the type hash of its payload, a sequence number per supplier and type (so consumers count
what they missed), the source time stamp and the publish time. Events pushed within one reactor
turn leave in one frame per topic (split at MAX_BATCH_EVENTS / MAX_BATCH_BYTES), so throughput
is not capped at one ZeroMQ message per event; at low rates that is one event per frame, as fast
as a single message; an event of LARGE_EVENT bytes or more travels alone, copied once into its
frame and decoded in place from the consumer's. Slow consumers never block suppliers: the
supplier's queue and ZeroMQ's are bounded (in bytes: transport.sockets), what overflows is
dropped and counted (`StructuredPushSupplier.dropped`), and the sequence numbers make the drops
visible (`StructuredPushConsumer.missed`). A consumer keeps the events waiting for its handler
as its quality of service says (keep-last depth, latest-only: transport.event_queue), so a slow
one gets recent events and counts what it skipped (`dropped`, `lag`). Suppliers and consumers
find their channel again when its host restarts elsewhere (transport.channel_link).
"""

from __future__ import annotations

import itertools
import random
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from struct import Struct
from struct import error as StructError
from typing import Any

import zmq

from miro_gen import clock
from miro_gen.log import logger
from miro_gen.runtime.cdr import encode_after, type_for_hash
from miro_gen.transport import offers, sockets
from miro_gen.transport.channel_link import ChannelLink
from miro_gen.transport.channels import (  # the channels' names, importable from here as before
    CHANNEL_REPO_ID as CHANNEL_REPO_ID,
)
from miro_gen.transport.channels import DEFAULT_CHANNEL as DEFAULT_CHANNEL
from miro_gen.transport.channels import PROXY_HWM as PROXY_HWM
from miro_gen.transport.channels import ChannelHost as ChannelHost
from miro_gen.transport.channels import EventChannel as EventChannel
from miro_gen.transport.channels import EventChannelFactory as EventChannelFactory
from miro_gen.transport.channels import resolve_channel as resolve_channel
from miro_gen.transport.event_queue import DEFAULT_DEPTH, EventQueue, Waiting
from miro_gen.transport.event_queue import KEEP_ALL as KEEP_ALL  # for consumers' depth=
from miro_gen.transport.gaps import GapCounter, gap

_log = logger("MIRO")

EVENT_VERSION = 1
HWM = 10_000  # frames a supplier's or a consumer's socket queues for one peer, at most
MAX_SUBSCRIPTIONS = 10_000  # prefixes a supplier tracks; beyond, it sends every topic
MAX_PREFIX = 4096  # bytes of a subscription prefix a supplier tracks
QUEUE_EVENTS = 100_000  # events a supplier holds for its reactor's next turn, at most
QUEUE_BYTES = 64 << 20  # and bytes
# Events from this size on travel alone, in a frame put together with one copy and handed to
# ZeroMQ without another (copy=False); consumers decode them from ZeroMQ's buffer, in place.
LARGE_EVENT = 64 * 1024
# Events in one frame, at most. The count is 16 bits, and a high-water mark counts frames: HWM
# frames must stay a bounded amount of memory. Yet frames must not be small: each send lets the
# pushing thread take the GIL back for up to a switch interval, so a flush in many frames falls
# behind a thread pushing flat out. An event larger than MAX_BATCH_BYTES travels alone.
MAX_BATCH_EVENTS = 16_384
MAX_BATCH_BYTES = 256 * 1024
TURN_EVENTS = 4096  # events a consumer delivers per reactor turn, so other handlers get a turn
TURN_FRAMES = 256  # frames a consumer reads per reactor turn
_BATCH = Struct("<BBHQ32s")  # version, flags, count, supplier id, type hash
_EVENT = Struct("<QqqI")  # sequence number, stamp ns, publish ns, payload length
_EVENT_SIZE = _EVENT.size
_LENGTH_AT = _BATCH.size + _EVENT_SIZE - 4  # the payload length of a frame's one event
_U32 = Struct("<I")
ANY = "*"


@dataclass(slots=True)
class StructuredEvent:
    """One event as a consumer receives it."""

    domain_name: str
    type_name: str
    payload: Any  # the decoded generated type
    seq: int
    stamp: float  # source time, seconds since the epoch
    publish_time: float  # when the supplier sent it, seconds since the epoch
    supplier: int = 0  # the supplier's random id
    type_hash: str = ""


def topic(domain: str, type_name: str) -> bytes:
    """The first frame of an event message; subscriptions are prefixes of it."""
    return domain.encode() + b"\0" + type_name.encode() + b"\0"


def subscription_prefix(domain: str, type_name: str) -> bytes:
    """What to subscribe to at the socket for (domain, type); `*` matches any. A `*` domain
    with a named type cannot be a prefix: it subscribes to all, and the consumer filters."""
    if domain == ANY:
        return b""
    if type_name == ANY:
        return domain.encode() + b"\0"
    return topic(domain, type_name)


class _Framed(list[bytes]):
    """A large event's whole batch frame: it travels alone."""


# ---- suppliers ------------------------------------------------------------------------------


class _Topic:
    """What a supplier keeps per type name: the topic frame, the sequence numbers, whether
    anyone subscribes (recomputed when the subscriptions change), the events not yet sent,
    whether the last event was large."""

    __slots__ = (
        "frame",
        "generation",
        "large",
        "last",
        "last_hash",
        "pending",
        "seq",
        "subscribed",
    )

    def __init__(self, frame: bytes) -> None:
        self.frame = frame
        self.large = False
        self.seq = itertools.count()
        self.generation = -1  # of the supplier's subscriptions that `subscribed` reflects
        self.subscribed = False
        # Runs of packed events with one type hash (one, unless the type changes), the last
        # run's list and hash.
        self.pending: list[tuple[str, list[bytes]]] = []
        self.last: list[bytes] = []
        self.last_hash = ""


class StructuredPushSupplier:
    """Pushes events into a channel. `push()` may be called from any thread; the sending
    happens on the reactor thread, once per turn for all events pushed meanwhile.

    Events wait for that turn in a bounded queue (QUEUE_EVENTS events, QUEUE_BYTES bytes): when
    the reactor cannot keep up, `push()` drops the newest and counts them in `dropped`, as it
    does those ZeroMQ refuses at its high-water mark, those larger than the maximum message
    size, and those pushed for subscribers while the channel is gone (its host died; the
    supplier finds it again when it is bound anew). Consumers see them as gaps."""

    def __init__(self, channel: EventChannel, domain_name: str | None = None) -> None:
        self.channel = channel
        self.domain_name = channel.domain_name if domain_name is None else domain_name
        self.reactor = channel.reactor
        self.supplier_id = random.getrandbits(63)
        self._topics: dict[str, _Topic] = {}
        self._dirty: list[_Topic] = []  # topics with pending events, in the order they came
        self._queued = 0
        self._queued_bytes = 0
        self._lock = threading.Lock()
        self._flush_pending = False
        self._subscriptions: dict[bytes, int] = {}
        self._generation = 0  # bumped whenever _subscriptions changes
        self._raw_hashes: dict[str, bytes] = {}
        self._offered: dict[str, str] = {}  # type name -> payload type hash, as described
        self.sent = 0
        self.dropped = 0  # events pushed while someone subscribed that were never sent
        self._too_large: set[str] = set()  # types with an event too large to send (said once)
        context = self.reactor.context
        self.max_frame = sockets.policy(context).max_message_size
        self.socket = sockets.connecting_socket(context, zmq.XPUB)
        # A turn's events leave in a burst of frames (100,000 small events: about 30), which the
        # socket must hold until the channel reads them: room for a full queue of batches
        # (QUEUE_BYTES), more only when the supplier's own events are larger than a batch.
        burst = QUEUE_BYTES // MAX_BATCH_BYTES
        self.socket.setsockopt(zmq.SNDHWM, min(HWM, max(burst, sockets.queue_limit(context))))
        self.socket.setsockopt(zmq.XPUB_VERBOSER, 1)
        # At the high-water mark an XPUB drops silently; with NODROP a non-blocking send fails
        # instead, so that the supplier counts what it drops. It never blocks either way.
        self.socket.setsockopt(zmq.XPUB_NODROP, 1)
        # No queue for a connection that is down: the channel's subscriptions end with it, and
        # what is pushed meanwhile is counted as dropped, not sent into the void.
        self.socket.setsockopt(zmq.IMMEDIATE, 1)
        self._connected = False
        self._lost: set[bytes] = set()  # the subscriptions when the channel went away
        resolve = channel.resolve
        self.link = ChannelLink(
            self.reactor,
            self.socket,
            channel.endpoints(context)[0],
            None if resolve is None else lambda: resolve().endpoints(context)[0],
            self._connection_changed,
        )
        self.reactor.call_soon(self.reactor.register, self.socket, self._subscription_changed)

    def _topic(self, type_name: str) -> _Topic:
        t = self._topics.get(type_name)
        if t is None:  # setdefault: two threads creating it at once share one counter
            t = self._topics.setdefault(type_name, _Topic(topic(self.domain_name, type_name)))
        return t

    def _subscribed(self, t: _Topic) -> bool:
        generation = self._generation
        if t.generation != generation:
            subs = list(self._subscriptions)
            t.subscribed = any(t.frame.startswith(p) for p in subs)
            t.generation = generation  # a change meanwhile bumped _generation: recomputed next
        return t.subscribed

    def has_subscribers(self, type_name: str) -> bool:
        """Whether any consumer subscribes to this supplier's events of `type_name`."""
        return self._subscribed(self._topic(type_name))

    def push(self, type_name: str, payload: Any, stamp: float | None = None) -> bool:
        """Publish `payload` (a generated type) as an event of `type_name`; False when nobody
        subscribes (nothing is encoded then). `stamp`: when the data was taken (default now, on the
        process's clock: the replayed time under `--clock log`)."""
        t = self._topics.get(type_name) or self._topic(type_name)
        offered = getattr(payload, "_type_hash", "")
        if self._offered.get(type_name) != offered:  # the first of its kind
            self._offered[type_name] = offered
            offers.offered(self.channel.name, self.domain_name, type_name, payload)
        seq = next(t.seq)
        if not (t.subscribed if t.generation == self._generation else self._subscribed(t)):
            if not self._connected and any(t.frame.startswith(p) for p in self._lost):
                with self._lock:  # subscribed when the channel went away: lost
                    self.dropped += 1
                return True
            return False
        now = clock.current().time_ns()  # log time under --clock log, else the wall clock
        type_hash = payload._type_hash
        stamp_ns = now if stamp is None else int(stamp * 1e9)
        packed, framed = self._encode(t, type_hash, (seq, stamp_ns, now), payload)
        size = len(framed or packed)
        if (size if framed else size + _BATCH.size) > self.max_frame:
            self._refuse_large(type_name, size)
            return True
        with self._lock:
            if self._queued >= QUEUE_EVENTS or self._queued_bytes + size > QUEUE_BYTES:
                self.dropped += 1
                return True
            if framed:  # alone, as it is
                if not t.pending:
                    self._dirty.append(t)
                t.pending.append((type_hash, _Framed((framed,))))
                t.last, t.last_hash = [], ""
            elif type_hash == t.last_hash and t.pending:
                t.last.append(packed)
            else:
                if not t.pending:
                    self._dirty.append(t)
                t.last, t.last_hash = [packed], type_hash
                t.pending.append((type_hash, t.last))
            self._queued += 1
            self._queued_bytes += size
            if self._flush_pending:
                return True
            self._flush_pending = True
        self.reactor.call_soon(self._flush)
        return True

    def _encode(
        self, t: _Topic, type_hash: str, head: tuple[int, int, int], payload: Any
    ) -> tuple[bytes, bytes]:
        """(event, b"") for a small event, to be batched; (b"", its whole frame) for a large
        one. Once a type's events are large, the next is encoded into its frame directly (its
        payload copied once); the payload length is filled in after."""
        if t.large:
            prefix = self._batch_head(type_hash, 1) + _EVENT.pack(*head, 0)
            buf = encode_after(prefix, payload)
            n = buf.size - len(prefix)
            buf.overwrite(_LENGTH_AT, _U32.pack(n))
            frame = buf.value()
            if n + _EVENT_SIZE >= LARGE_EVENT:
                return b"", frame
            t.large = False
            return frame[_BATCH.size :], b""
        data = payload.serialize()
        packed = _EVENT.pack(*head, len(data))
        if len(packed) + len(data) < LARGE_EVENT:
            return packed + data, b""
        t.large = True
        return b"", b"".join((self._batch_head(type_hash, 1), packed, data))

    def _batch_head(self, type_hash: str, count: int) -> bytes:
        raw = self._raw_hashes.get(type_hash)
        if raw is None:
            raw = self._raw_hashes[type_hash] = bytes.fromhex(type_hash)
        return _BATCH.pack(EVENT_VERSION, 0, count, self.supplier_id, raw)

    def _flush(self) -> None:
        with self._lock:
            topics, self._dirty = self._dirty, []
            queues = []
            for t in topics:
                queues.append((t.frame, t.pending))
                t.pending, t.last, t.last_hash = [], [], ""
            self._queued = self._queued_bytes = 0
            self._flush_pending = False
        for frame, runs in queues:
            for type_hash, events in runs:
                if type(events) is _Framed:
                    self._send_body(frame, events[0], 1)
                    continue
                if len(events) <= MAX_BATCH_EVENTS and sum(map(len, events)) <= MAX_BATCH_BYTES:
                    self._send(frame, type_hash, events)
                    continue
                batch: list[bytes] = []
                size = 0
                for packed in events:  # a busy turn: several frames, within the limits
                    if batch and (
                        len(batch) == MAX_BATCH_EVENTS or size + len(packed) > MAX_BATCH_BYTES
                    ):
                        self._send(frame, type_hash, batch)
                        batch, size = [], 0
                    batch.append(packed)
                    size += len(packed)
                self._send(frame, type_hash, batch)

    def _send(self, frame: bytes, type_hash: str, packed: list[bytes]) -> None:
        """One frame of the events `packed`."""
        body = b"".join([self._batch_head(type_hash, len(packed)), *packed])
        self._send_body(frame, body, len(packed))

    def _send_body(self, frame: bytes, body: bytes, count: int) -> None:
        if self._send_frame(frame, body):
            self.sent += count
        else:  # at the high-water mark: dropped, visible as a gap
            with self._lock:
                self.dropped += count

    def _send_frame(self, frame: bytes, body: bytes) -> bool:
        """Send a topic frame and a batch frame (large ones without a copy); False at the
        high-water mark, or when the channel is gone (nobody to send to: the events are lost)."""
        if not self._connected:
            return False
        try:
            self.socket.send_multipart([frame, body], zmq.NOBLOCK, copy=len(body) < LARGE_EVENT)
        except zmq.Again:
            return False
        return True

    def _refuse_large(self, type_name: str, size: int) -> None:
        with self._lock:
            self.dropped += 1
        if type_name not in self._too_large and len(self._too_large) < 1000:
            self._too_large.add(type_name)
            _log.warning(
                "dropped a %s event of %d bytes: more than the maximum message size "
                "(%d; --max-message-size)",
                type_name,
                size,
                self.max_frame,
            )

    def _connection_changed(self, up: bool) -> None:
        """The connection to the channel came up or went down (reactor thread)."""
        if up:
            self._lost = set()
        else:
            self._lost = set(self._subscriptions)
            _log.notice("lost the event channel %s; looking for it", self.channel.name)
        self._connected = up

    def _subscription_changed(self) -> None:
        # A lost connection's subscriptions end with unsubscriptions that ZeroMQ queues after
        # its monitor event: read that event first, so that `_lost` still holds them.
        self.link.read_events()
        changed = False
        subs = self._subscriptions
        while True:
            try:
                msg = self.socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                break
            if not msg:
                continue
            prefix = msg[1 : MAX_PREFIX + 1]  # a longer prefix matches no fewer topics
            if prefix not in subs and len(subs) >= MAX_SUBSCRIPTIONS:
                prefix = b""  # too many to track: send every topic (the channel filters)
            n = subs.get(prefix, 0) + (1 if msg[0] == 1 else -1)
            if n > 0:
                subs[prefix] = n
            else:
                subs.pop(prefix, None)
            changed = True
        if changed:
            self._generation += 1  # after the change, so a reader never keeps a stale answer

    def close(self) -> None:
        self.link.close_socket()


# ---- consumers ------------------------------------------------------------------------------


class StructuredPushConsumer:
    """Receives the events it subscribes to. Subclass it and override
    `push_structured_event(event)`; it runs on the reactor thread, so it must not block.

    Events wait for the handler in a queue kept as `depth` says (transport.event_queue): the
    newest 10 per topic by default, as ROS 2 keeps them; `latest_only` keeps the newest one;
    `depth=KEEP_ALL` keeps everything up to the queue's byte limit. `missed` counts events lost
    on the way (sequence gaps), `dropped` those this consumer skipped because its handler fell
    behind, `lag` how old (seconds since it was pushed) the last event delivered was."""

    def __init__(
        self, channel: EventChannel, *, depth: int = DEFAULT_DEPTH, latest_only: bool = False
    ) -> None:
        self.channel = channel
        self.reactor = channel.reactor
        self.queue = EventQueue(depth, latest_only)
        context = self.reactor.context
        self.socket = sockets.connecting_socket(context, zmq.SUB)
        self.socket.setsockopt(zmq.RCVHWM, min(HWM, sockets.queue_limit(context)))
        resolve = channel.resolve
        self.link = ChannelLink(
            self.reactor,
            self.socket,
            channel.endpoints(context)[1],
            None if resolve is None else lambda: resolve().endpoints(context)[1],
            lambda up: None,
        )
        self._filters: list[tuple[str, str]] = []
        self._prefixes: set[bytes] = set()
        self._gaps = GapCounter()  # per (supplier, type name), bounded
        self._topics: dict[bytes, tuple[str, str, bool]] = {}
        self._classes: dict[bytes, type[Any]] = {}
        self._unknown: set[tuple[str, str]] = set()
        self._scheduled = False
        self.received = 0
        self.undecodable = 0  # events whose type hash matches no imported generated type
        self.lag = 0.0  # seconds between the push and the delivery of the last event delivered
        self.reactor.call_soon(self.reactor.register, self.socket, self._readable)

    @property
    def missed(self) -> int:
        """Events lost between their suppliers and this consumer (sequence gaps)."""
        return self._gaps.missed

    @property
    def dropped(self) -> int:
        """Events received but skipped: the handler fell behind (depth, latest-only)."""
        return self.queue.dropped

    def set_subscriptions(self, subscriptions: Iterable[tuple[str, str]]) -> None:
        """Receive the events of these (domain, type) pairs, `*` for any; replaces the last."""
        subs = [(d, t) for d, t in subscriptions]
        prefixes = {subscription_prefix(d, t) for d, t in subs}
        offers.subscribed(self, self.channel.name, subs)

        def apply() -> None:
            for p in self._prefixes - prefixes:
                self.socket.setsockopt(zmq.UNSUBSCRIBE, p)
            for p in prefixes - self._prefixes:
                self.socket.setsockopt(zmq.SUBSCRIBE, p)
            self._prefixes = prefixes
            self._filters = subs
            self._topics.clear()

        self.reactor.call_soon(apply)

    def push_structured_event(self, event: StructuredEvent) -> None:
        """Called for each event received (override it)."""

    def _wanted(self, domain: str, type_name: str) -> bool:
        return any((d in (ANY, domain)) and (t in (ANY, type_name)) for d, t in self._filters)

    def _readable(self) -> None:
        """Take every frame waiting (so that the queue, not ZeroMQ, decides what waits), then
        deliver a turn's worth of events."""
        recv, queue = self.socket.recv_multipart, self.queue
        for _ in range(TURN_FRAMES):
            try:
                parts = recv(zmq.NOBLOCK, copy=False)  # large payloads are decoded in place
            except zmq.Again:
                break
            try:
                self._parse(parts)
            except (ValueError, StructError, UnicodeDecodeError) as e:
                _log.warning("dropped an event frame on %s: %s", self.channel.name, e)
        else:
            self._schedule()  # more frames may wait: read them next turn
        if len(queue):
            self._deliver()

    def _schedule(self) -> None:
        if not self._scheduled:
            self._scheduled = True
            self.reactor.call_soon(self._resume)

    def _resume(self) -> None:
        self._scheduled = False
        self._readable()

    def _deliver(self) -> None:
        deliver, queue, reactor = self.push_structured_event, self.queue, self.reactor
        pop = queue.pop
        n = 0
        while n < TURN_EVENTS and not reactor.stopping:
            w = pop()
            if w is None:
                break
            event = w.event
            try:
                event.payload = w.cls.deserialize(event.payload)
            except Exception as e:  # MARSHAL: a corrupt payload is reported, not delivered
                _log.warning("dropped an undecodable %s event: %s", event.type_name, e)
                continue
            n += 1
            self.lag = time.time() - event.publish_time
            try:
                deliver(event)
            except Exception:
                _log.exception("push_structured_event failed on %s", event.type_name)
        self.received += n
        if len(queue) and not reactor.stopping:
            self._schedule()  # the rest next turn: other handlers get theirs meanwhile

    def _topic(self, head: bytes) -> tuple[str, str, bool]:
        """(domain, type name, whether subscribed) of a topic frame."""
        known = self._topics.get(head)
        if known is None:
            fields = head.split(b"\0")
            if len(fields) != 3 or fields[2]:
                raise ValueError("malformed topic")
            domain, type_name = fields[0].decode(), fields[1].decode()
            known = (domain, type_name, self._wanted(domain, type_name))
            if len(self._topics) >= 4096:  # a bounded cache, whatever the channel carries
                self._topics.clear()
            self._topics[head] = known
        return known

    def _class(self, raw_hash: bytes, domain: str, type_name: str) -> type[Any] | None:
        """The generated type of payloads with this type hash; None (reported once) if none."""
        cls = self._classes.get(raw_hash)
        if cls is None:
            type_hash = raw_hash.hex()
            cls = type_for_hash(type_hash)
            if cls is not None:
                self._classes[raw_hash] = cls
            elif (type_name, type_hash) not in self._unknown and len(self._unknown) < 1000:
                self._unknown.add((type_name, type_hash))
                _log.warning(
                    "events %s/%s have type hash %s, which no imported generated type has: "
                    "dropped (import the type's generated module, or regenerate it)",
                    domain,
                    type_name,
                    type_hash[:12],
                )
        return cls

    def _parse(self, parts: list[zmq.Frame]) -> None:
        """Queue the events of one message; raises if the frame does not parse (then none of
        its events count, and the sequence numbers stay as they were)."""
        if len(parts) != 2:
            raise ValueError(f"{len(parts)} frames, expected 2")
        head, body = parts[0].bytes, parts[1].buffer  # the body is not copied
        domain, type_name, wanted = self._topic(head)
        if not wanted:
            return
        version, _, count, supplier, raw_hash = _BATCH.unpack_from(body)
        if version != EVENT_VERSION:
            raise ValueError(f"event version {version} is not supported")
        cls = self._class(raw_hash, domain, type_name)
        type_hash = raw_hash.hex()
        expected = self._gaps.expected(supplier, type_name)
        first = expected
        missed = 0
        unpack, size, at = _EVENT.unpack_from, len(body), _BATCH.size
        topic_key = (domain, type_name)
        waiting = []
        keep_from = count - 1 if self.queue.latest_only else 0  # latest-only: only the last
        for i in range(count):
            seq, stamp_ns, publish_ns, n = unpack(body, at)
            at += _EVENT_SIZE
            if at + n > size:
                raise ValueError("event payload is truncated")
            missed += gap(expected, seq)
            expected = seq + 1
            if cls is not None and i >= keep_from:
                # Decoded when delivered; a small payload is copied out, so that a batch's
                # frame is not kept for one event that waits.
                data = body[at : at + n] if n >= LARGE_EVENT else bytes(body[at : at + n])
                event = StructuredEvent(
                    domain,
                    type_name,
                    data,
                    seq,
                    stamp_ns / 1e9,
                    publish_ns / 1e9,
                    supplier,
                    type_hash,
                )
                waiting.append(Waiting(topic_key, event, cls, n))
            at += n
        if at != size:
            raise ValueError("trailing bytes after the events")
        # Only a frame that parses to its end moves the sequence numbers.
        if expected is not None and expected != first:
            self._gaps.advance(supplier, type_name, expected, missed)
        if cls is None:
            self.undecodable += count
        elif waiting:
            self.queue.dropped += keep_from
            self.queue.add(topic_key, waiting)

    def close(self) -> None:
        offers.unsubscribed(self)
        self.link.close_socket()
