"""Event channels: suppliers push typed events, any number of consumers receive those they
subscribe to (Miro's EventChannel, StructuredPushSupplier, StructuredPushConsumer).

A channel is a ZeroMQ XSUB/XPUB proxy, run by libzmq in a thread of the process that hosts it,
and bound in the naming service (docs/PROTOCOL.md, "Event channels"). Suppliers connect XPUB
sockets to its XSUB side, so subscriptions travel back to them: `has_subscribers()` tells a
supplier whether anyone listens, and `push()` skips encoding when nobody does. Consumers connect
SUB sockets to its XPUB side.

Each event carries its domain (by convention the supplier's naming context: the robot), its type
name, the type hash of its payload, a per-supplier sequence number (so consumers count what they
missed), the source time stamp and the publish time. Events pushed within one reactor turn leave
in one frame per topic; at low rates that is one event per frame, as fast as a single message.
Slow consumers never block suppliers: ZeroMQ drops at its high-water marks, and the sequence
numbers make the drops visible (`StructuredPushConsumer.missed`).
"""

from __future__ import annotations

import itertools
import os
import random
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from struct import Struct
from struct import error as StructError
from typing import Any

import MiroNaming
import zmq

from miro_gen.log import logger
from miro_gen.runtime.cdr import type_for_hash
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")

CHANNEL_REPO_ID = "IDL:miro-gen/EventChannel:1.0"
DEFAULT_CHANNEL = "EventChannel"
EVENT_VERSION = 1
HWM = 10_000  # events a socket queues for one peer before dropping
_BATCH = Struct("<BBHQ32s")  # version, flags, count, supplier id, type hash
_EVENT = Struct("<QqqI")  # sequence number, stamp ns, publish ns, payload length
ANY = "*"


@dataclass
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


class StructuredPushSupplier:
    """Pushes events into a channel. `push()` may be called from any thread; the sending
    happens on the reactor thread, once per turn for all events pushed meanwhile."""

    def __init__(self, channel: EventChannel, domain_name: str | None = None) -> None:
        self.channel = channel
        self.domain_name = channel.domain_name if domain_name is None else domain_name
        self.reactor = channel.reactor
        self.supplier_id = random.getrandbits(63)
        self._seq = itertools.count()
        self._queue: dict[str, list[tuple[int, int, bytes, str]]] = {}
        self._lock = threading.Lock()
        self._flush_pending = False
        self._subscriptions: dict[bytes, int] = {}
        self.sent = 0
        self.socket = self.reactor.context.socket(zmq.XPUB)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.SNDHWM, HWM)
        self.socket.setsockopt(zmq.XPUB_VERBOSER, 1)
        self.socket.connect(channel.supplier_endpoint)
        self.reactor.call_soon(self.reactor.register, self.socket, self._subscription_changed)

    def has_subscribers(self, type_name: str) -> bool:
        """Whether any consumer subscribes to this supplier's events of `type_name`."""
        t = topic(self.domain_name, type_name)
        return any(n > 0 and t.startswith(p) for p, n in list(self._subscriptions.items()))

    def push(self, type_name: str, payload: Any, stamp: float | None = None) -> bool:
        """Publish `payload` (a generated type) as an event of `type_name`; False when nobody
        subscribes (nothing is encoded then). `stamp`: when the data was taken (default now)."""
        seq = next(self._seq)
        if not self.has_subscribers(type_name):
            return False
        stamp_ns = time.time_ns() if stamp is None else int(stamp * 1e9)
        data = payload.serialize()
        with self._lock:
            self._queue.setdefault(type_name, []).append((seq, stamp_ns, data, payload._type_hash))
            schedule = not self._flush_pending
            self._flush_pending = True
        if schedule:
            self.reactor.call_soon(self._flush)
        return True

    def _flush(self) -> None:
        with self._lock:
            queue, self._queue = self._queue, {}
            self._flush_pending = False
        publish_ns = time.time_ns()
        for type_name, events in queue.items():
            for type_hash, group in itertools.groupby(events, key=lambda e: e[3]):
                batch = list(group)
                parts = [
                    _BATCH.pack(
                        EVENT_VERSION, 0, len(batch), self.supplier_id, bytes.fromhex(type_hash)
                    )
                ]
                for seq, stamp_ns, data, _ in batch:
                    parts.append(_EVENT.pack(seq, stamp_ns, publish_ns, len(data)))
                    parts.append(data)
                try:
                    self.socket.send_multipart(
                        [topic(self.domain_name, type_name), b"".join(parts)], zmq.NOBLOCK
                    )
                    self.sent += len(batch)
                except zmq.Again:  # at the high-water mark: dropped, visible as a gap
                    pass

    def _subscription_changed(self) -> None:
        while True:
            try:
                msg = self.socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            if not msg:
                continue
            prefix = msg[1:]
            n = self._subscriptions.get(prefix, 0) + (1 if msg[0] == 1 else -1)
            if n > 0:
                self._subscriptions[prefix] = n
            else:
                self._subscriptions.pop(prefix, None)

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
        self._next_seq: dict[int, int] = {}
        self._unknown: set[tuple[str, str]] = set()
        self.received = 0
        self.missed = 0  # events lost between suppliers and this consumer
        self.undecodable = 0  # events whose type hash matches no imported generated type
        self.reactor.call_soon(self.reactor.register, self.socket, self._readable)

    def set_subscriptions(self, subscriptions: Iterable[tuple[str, str]]) -> None:
        """Receive the events of these (domain, type) pairs, `*` for any; replaces the last."""
        subs = [(d, t) for d, t in subscriptions]
        prefixes = {subscription_prefix(d, t) for d, t in subs}

        def apply() -> None:
            for p in self._prefixes - prefixes:
                self.socket.setsockopt(zmq.UNSUBSCRIBE, p)
            for p in prefixes - self._prefixes:
                self.socket.setsockopt(zmq.SUBSCRIBE, p)
            self._prefixes = prefixes
            self._filters = subs

        self.reactor.call_soon(apply)

    def push_structured_event(self, event: StructuredEvent) -> None:
        """Called for each event received (override it)."""

    def _wanted(self, domain: str, type_name: str) -> bool:
        return any((d in (ANY, domain)) and (t in (ANY, type_name)) for d, t in self._filters)

    def _readable(self) -> None:
        for _ in range(1000):
            try:
                parts = self.socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            try:
                events = self._parse(parts)
            except (ValueError, StructError, UnicodeDecodeError) as e:
                _log.warning("dropped an event frame on %s: %s", self.channel.name, e)
                continue
            for event in events:
                self.received += 1
                try:
                    self.push_structured_event(event)
                except Exception:
                    _log.exception("push_structured_event failed on %s", event.type_name)

    def _parse(self, parts: list[bytes]) -> list[StructuredEvent]:
        if len(parts) != 2:
            raise ValueError(f"{len(parts)} frames, expected 2")
        head, body = parts
        fields = head.split(b"\0")
        if len(fields) != 3 or fields[2]:
            raise ValueError("malformed topic")
        domain, type_name = fields[0].decode(), fields[1].decode()
        if not self._wanted(domain, type_name):
            return []
        version, _, count, supplier, raw_hash = _BATCH.unpack_from(body)
        if version != EVENT_VERSION:
            raise ValueError(f"event version {version} is not supported")
        type_hash = raw_hash.hex()
        cls = type_for_hash(type_hash)
        at = _BATCH.size
        out = []
        for _ in range(count):
            seq, stamp_ns, publish_ns, n = _EVENT.unpack_from(body, at)
            at += _EVENT.size
            data = body[at : at + n]
            if len(data) != n:
                raise ValueError("event payload is truncated")
            at += n
            expected = self._next_seq.get(supplier)
            if expected is not None and seq > expected:
                self.missed += seq - expected
            self._next_seq[supplier] = seq + 1
            if cls is None:
                self.undecodable += 1
                if (type_name, type_hash) not in self._unknown:
                    self._unknown.add((type_name, type_hash))
                    _log.warning(
                        "events %s/%s have type hash %s, which no imported generated type has: "
                        "dropped (import the type's generated module, or regenerate it)",
                        domain,
                        type_name,
                        type_hash[:12],
                    )
                continue
            try:
                payload = cls.deserialize(data)  # type: ignore[attr-defined]
            except Exception as e:  # MARSHAL: a corrupt payload is reported, not delivered
                _log.warning("dropped an undecodable %s event: %s", type_name, e)
                continue
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
        if at != len(body):
            raise ValueError("trailing bytes after the events")
        return out

    def close(self) -> None:
        _close_on(self.reactor, self.socket)
