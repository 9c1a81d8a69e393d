"""Event channels: suppliers push typed events, any number of consumers receive those they
subscribe to (Miro's EventChannel, StructuredPushSupplier, StructuredPushConsumer).

A channel is a ZeroMQ XSUB/XPUB proxy, run by libzmq in a thread of the process that hosts it,
and bound in the naming service (docs/PROTOCOL.md, "Event channels"). Suppliers connect XPUB
sockets to its XSUB side, so subscriptions travel back to them: `has_subscribers()` tells a
supplier whether anyone listens, and `push()` skips encoding when nobody does. Consumers connect
SUB sockets to its XPUB side.

Each event carries its domain (by convention the supplier's naming context: the robot), its type
name, the type hash of its payload, a sequence number per supplier and type (so consumers count
what they missed), the source time stamp and the publish time. Events pushed within one reactor
turn leave in one frame per topic (split at MAX_BATCH_EVENTS / MAX_BATCH_BYTES), so throughput
is not capped at one ZeroMQ message per event; at low rates that is one event per frame, as fast
as a single message. Slow consumers never block suppliers: the supplier's queue and ZeroMQ's are
bounded, what overflows is dropped and counted (`StructuredPushSupplier.dropped`), and the
sequence numbers make the drops visible (`StructuredPushConsumer.missed`).
"""

from __future__ import annotations

import itertools
import os
import random
import threading
from collections.abc import Iterable
from dataclasses import dataclass, field
from struct import Struct
from struct import error as StructError
from typing import Any

import MiroNaming
import zmq

from miro_gen import clock
from miro_gen.log import logger
from miro_gen.runtime.cdr import type_for_hash
from miro_gen.transport import offers
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")

CHANNEL_REPO_ID = "IDL:miro-gen/EventChannel:1.0"
DEFAULT_CHANNEL = "EventChannel"
EVENT_VERSION = 1
HWM = 10_000  # events a socket queues for one peer before dropping
QUEUE_EVENTS = 100_000  # events a supplier holds for its reactor's next turn, at most
QUEUE_BYTES = 64 << 20  # and bytes
# Events in one frame, at most. The count is 16 bits, and a high-water mark counts frames: HWM
# frames must stay a bounded amount of memory. Yet frames must not be small: each send lets the
# pushing thread take the GIL back for up to a switch interval, so a flush in many frames falls
# behind a thread pushing flat out. An event larger than MAX_BATCH_BYTES travels alone.
MAX_BATCH_EVENTS = 16_384
MAX_BATCH_BYTES = 256 * 1024
TURN_EVENTS = 4096  # events a consumer delivers per reactor turn, so other handlers get a turn
_BATCH = Struct("<BBHQ32s")  # version, flags, count, supplier id, type hash
_EVENT = Struct("<QqqI")  # sequence number, stamp ns, publish ns, payload length
_EVENT_SIZE = _EVENT.size
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


def _close_on(reactor: Reactor, socket: zmq.Socket[Any]) -> None:
    """Close a socket of the reactor's thread, on that thread."""

    def close() -> None:
        reactor.unregister(socket)
        socket.close(0)

    reactor.call_soon(close)


# ---- channels -------------------------------------------------------------------------------


@dataclass
class EventChannel:
    """Where a channel's suppliers (`supplier_endpoint`) and consumers (`consumer_endpoint`)
    connect; `reactor` is the process's, which suppliers and consumers made from it use."""

    name: str
    supplier_endpoint: str
    consumer_endpoint: str
    reactor: Reactor
    domain_name: str = ""  # the default domain of suppliers (the process's naming context)
    _host: ChannelHost | None = field(default=None, repr=False)


class ChannelHost:
    """Runs a channel's XSUB/XPUB proxy in a thread (libzmq's, without the GIL) until closed:
    in the process that creates the channel, or in `miro naming --channel`."""

    def __init__(self, context: zmq.Context[Any], bind_host: str, advertise: str) -> None:
        self.xsub = context.socket(zmq.XSUB)
        self.xpub = context.socket(zmq.XPUB)
        for s in (self.xsub, self.xpub):
            s.setsockopt(zmq.LINGER, 0)
            s.setsockopt(zmq.SNDHWM, HWM)
            s.setsockopt(zmq.RCVHWM, HWM)
        self.xpub.setsockopt(zmq.XPUB_VERBOSER, 1)  # every (un)subscription reaches suppliers
        port_in = self.xsub.bind_to_random_port(f"tcp://{bind_host}")
        port_out = self.xpub.bind_to_random_port(f"tcp://{bind_host}")
        self.supplier_endpoint = f"tcp://{advertise}:{port_in}"
        self.consumer_endpoint = f"tcp://{advertise}:{port_out}"
        control_name = f"inproc://miro-channel-{os.getpid()}-{id(self)}"
        self.control = context.socket(zmq.PAIR)
        self.control.bind(control_name)
        self._peer = context.socket(zmq.PAIR)
        self._peer.connect(control_name)
        self.thread = threading.Thread(target=self._run, name="miro-channel", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            zmq.proxy_steerable(self.xsub, self.xpub, None, self._peer)
        except zmq.ZMQError as e:  # the context is terminating
            _log.debug("event channel proxy ended: %s", e)
        finally:
            for s in (self.xsub, self.xpub, self._peer):
                s.close(0)

    def close(self) -> None:
        self.control.send(b"TERMINATE")
        self.thread.join(5)
        self.control.close(0)


class EventChannelFactory:
    """Creates event channels hosted by `server`'s process and bound in its naming context."""

    def __init__(self, server: Any) -> None:
        self.server = server
        # The channels this process hosts, whichever factory created them.
        self._channels: dict[str, EventChannel] = server.hosted_channels

    def create_channel(self, name: str = DEFAULT_CHANNEL) -> EventChannel:
        """Host a channel and bind it as `name`; the one already hosted here if there is one."""
        full = self.server.naming.full_name(name)
        if full in self._channels:
            return self._channels[full]
        # Bound and advertised like the server's objects (miro_gen.transport.addresses).
        advertise = self.server.adapter.endpoint.split("://", 1)[1].rsplit(":", 1)[0]
        ch_host = ChannelHost(self.server.context, self.server.addresses.bind, advertise)
        channel = EventChannel(
            full,
            ch_host.supplier_endpoint,
            ch_host.consumer_endpoint,
            self.server.reactor(),
            self.server.options.naming_context,
            ch_host,
        )
        entry = MiroNaming.Entry(
            full, CHANNEL_REPO_ID, ch_host.supplier_endpoint, ch_host.consumer_endpoint.encode(), ""
        )
        self.server.bind_entry(entry)
        self.server.on_shutdown(ch_host.close)
        self._channels[full] = channel
        return channel

    def find_or_create_channel(self, name: str = DEFAULT_CHANNEL) -> EventChannel:
        """The channel bound as `name` (in this process's context, then at the root: one that
        `miro naming --channel` or another service hosts), else one hosted here."""
        hosted = self._channels.get(self.server.naming.full_name(name))
        if hosted is not None:
            return hosted
        try:
            return resolve_channel(self.server, name)
        except MiroNaming.NotFound:
            return self.create_channel(name)


def resolve_channel(server: Any, name: str = DEFAULT_CHANNEL) -> EventChannel:
    """The channel bound as `name` (naming rules as for objects)."""
    entry = server.naming.resolve(name)
    if entry.repo_id != CHANNEL_REPO_ID:
        raise MiroNaming.NotFound(name=f"{entry.name} (bound, but not an event channel)")
    return EventChannel(
        entry.name,
        entry.endpoint,
        bytes(entry.key).decode(),
        server.reactor(),
        server.options.naming_context,
    )


# ---- suppliers ------------------------------------------------------------------------------


class _Topic:
    """What a supplier keeps per type name: the topic frame, the sequence numbers, whether
    anyone subscribes (recomputed when the subscriptions change), the events not yet sent."""

    __slots__ = ("frame", "generation", "last", "last_hash", "pending", "seq", "subscribed")

    def __init__(self, frame: bytes) -> None:
        self.frame = frame
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
    does those ZeroMQ refuses at its high-water mark. Consumers see them as gaps."""

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
        self.socket = self.reactor.context.socket(zmq.XPUB)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.SNDHWM, HWM)
        self.socket.setsockopt(zmq.XPUB_VERBOSER, 1)
        # At the high-water mark an XPUB drops silently; with NODROP a non-blocking send fails
        # instead, so that the supplier counts what it drops. It never blocks either way.
        self.socket.setsockopt(zmq.XPUB_NODROP, 1)
        self.socket.connect(channel.supplier_endpoint)
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
            return False
        now = clock.current().time_ns()  # log time under --clock log, else the wall clock
        data = payload.serialize()
        packed = _EVENT.pack(seq, now if stamp is None else int(stamp * 1e9), now, len(data))
        packed += data
        with self._lock:
            if self._queued >= QUEUE_EVENTS or self._queued_bytes + len(packed) > QUEUE_BYTES:
                self.dropped += 1
                return True
            type_hash = payload._type_hash
            if type_hash == t.last_hash and t.pending:
                t.last.append(packed)
            else:
                if not t.pending:
                    self._dirty.append(t)
                t.last, t.last_hash = [packed], type_hash
                t.pending.append((type_hash, t.last))
            self._queued += 1
            self._queued_bytes += len(packed)
            if self._flush_pending:
                return True
            self._flush_pending = True
        self.reactor.call_soon(self._flush)
        return True

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
        raw = self._raw_hashes.get(type_hash)
        if raw is None:
            raw = self._raw_hashes[type_hash] = bytes.fromhex(type_hash)
        head = _BATCH.pack(EVENT_VERSION, 0, len(packed), self.supplier_id, raw)
        try:
            self.socket.send_multipart([frame, head + b"".join(packed)], zmq.NOBLOCK)
            self.sent += len(packed)
        except zmq.Again:  # at the high-water mark: dropped, visible as a gap
            with self._lock:
                self.dropped += len(packed)

    def _subscription_changed(self) -> None:
        changed = False
        while True:
            try:
                msg = self.socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                break
            if not msg:
                continue
            prefix = msg[1:]
            n = self._subscriptions.get(prefix, 0) + (1 if msg[0] == 1 else -1)
            if n > 0:
                self._subscriptions[prefix] = n
            else:
                self._subscriptions.pop(prefix, None)
            changed = True
        if changed:
            self._generation += 1  # after the change, so a reader never keeps a stale answer

    def close(self) -> None:
        _close_on(self.reactor, self.socket)


# ---- consumers ------------------------------------------------------------------------------


class StructuredPushConsumer:
    """Receives the events it subscribes to. Subclass it and override
    `push_structured_event(event)`; it runs on the reactor thread, so it must not block."""

    def __init__(self, channel: EventChannel) -> None:
        self.channel = channel
        self.reactor = channel.reactor
        self.socket = self.reactor.context.socket(zmq.SUB)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.RCVHWM, HWM)
        self.socket.connect(channel.consumer_endpoint)
        self._filters: list[tuple[str, str]] = []
        self._prefixes: set[bytes] = set()
        self._next_seq: dict[tuple[int, str], int] = {}  # per (supplier, type name)
        self._topics: dict[bytes, tuple[str, str, bool]] = {}
        self._classes: dict[bytes, type[Any]] = {}
        self._unknown: set[tuple[str, str]] = set()
        self.received = 0
        self.missed = 0  # events lost between suppliers and this consumer
        self.undecodable = 0  # events whose type hash matches no imported generated type
        self.reactor.call_soon(self.reactor.register, self.socket, self._readable)

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
        recv, deliver = self.socket.recv_multipart, self.push_structured_event
        reactor = self.reactor
        delivered = 0
        while delivered < TURN_EVENTS:  # the poller reports the rest in the next turn
            try:
                parts = recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            delivered += 1  # a frame counts, even one that is dropped
            try:
                events = self._parse(parts)
            except (ValueError, StructError, UnicodeDecodeError) as e:
                _log.warning("dropped an event frame on %s: %s", self.channel.name, e)
                continue
            n = 0
            for event in events:
                if reactor.stopping:  # a slow consumer's backlog must not delay the shutdown
                    break
                try:
                    deliver(event)
                except Exception:
                    _log.exception("push_structured_event failed on %s", event.type_name)
                n += 1
            self.received += n
            delivered += n
            if n < len(events):
                return

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
            elif (type_name, type_hash) not in self._unknown:
                self._unknown.add((type_name, type_hash))
                _log.warning(
                    "events %s/%s have type hash %s, which no imported generated type has: "
                    "dropped (import the type's generated module, or regenerate it)",
                    domain,
                    type_name,
                    type_hash[:12],
                )
        return cls

    def _parse(self, parts: list[bytes]) -> list[StructuredEvent]:
        """The events of one message, decoded; raises if the frame does not parse (then none
        of its events count, and the sequence numbers stay as they were)."""
        if len(parts) != 2:
            raise ValueError(f"{len(parts)} frames, expected 2")
        head, body = parts
        domain, type_name, wanted = self._topic(head)
        if not wanted:
            return []
        version, _, count, supplier, raw_hash = _BATCH.unpack_from(body)
        if version != EVENT_VERSION:
            raise ValueError(f"event version {version} is not supported")
        cls = self._class(raw_hash, domain, type_name)
        deserialize = None if cls is None else cls.deserialize
        type_hash = raw_hash.hex()
        key = (supplier, type_name)
        expected = self._next_seq.get(key)
        missed = 0
        unpack, size, at = _EVENT.unpack_from, len(body), _BATCH.size
        out = []
        for _ in range(count):
            seq, stamp_ns, publish_ns, n = unpack(body, at)
            at += _EVENT_SIZE
            if at + n > size:
                raise ValueError("event payload is truncated")
            if expected is not None and seq > expected:
                missed += seq - expected
            expected = seq + 1
            if deserialize is None:
                at += n
                continue
            try:
                payload = deserialize(body[at : at + n])
            except Exception as e:  # MARSHAL: a corrupt payload is reported, not delivered
                _log.warning("dropped an undecodable %s event: %s", type_name, e)
                at += n
                continue
            at += n
            out.append(
                StructuredEvent(
                    domain,
                    type_name,
                    payload,
                    seq,
                    stamp_ns / 1e9,
                    publish_ns / 1e9,
                    supplier,
                    type_hash,
                )
            )
        if at != size:
            raise ValueError("trailing bytes after the events")
        # Only a frame that parses to its end moves the sequence numbers.
        if expected is not None:
            self._next_seq[key] = expected
        self.missed += missed
        if deserialize is None:
            self.undecodable += count
        return out

    def close(self) -> None:
        offers.unsubscribed(self)
        _close_on(self.reactor, self.socket)
