"""The Notification door of an event channel: one channel, two doors.

A process that hosts an event channel (a `Server` with an IIOP side, `miro naming
--iiop-endpoint`) serves it as a `CosNotifyChannelAdmin::EventChannel` too (miro_gen.corba.notify),
and this module joins the two doors through the channel's own ZeroMQ proxy, in-process:

* an event a CORBA supplier pushes is published into the channel, as the generated type's CDR,
  by a `StructuredPushSupplier` of the door per CORBA supplier and domain (its own supplier id
  and sequence numbers: consumers count what they miss, recorders record it as any other), and
  only when a ZeroMQ consumer subscribes to its topic;
* the door's raw consumer (`_Tap`) subscribes to what the CORBA consumers subscribe to and
  hands those events, payloads undecoded, to the hub, which pushes them to the CORBA
  consumers; the door's own events are recognised by their supplier ids and skipped;
* a raw XPUB socket (`_Watch`) learns what the ZeroMQ consumers subscribe to, which the CORBA
  suppliers see (`obtain_subscription_types`, `subscription_change`).

The tap's subscriptions are prefixes that no ZeroMQ consumer uses (`domain\\0type`, without the
final NUL; `domain` for a whole domain), so that what others subscribe to stays apart from
what the door asks for itself.

The channel is bound as one naming entry for both doors: an IOR whose IIOP profile is the
Notification door and whose miro-gen profile (`TAG_MIRO_ZMQ`) holds the ZeroMQ endpoints
(`channel_entry`; `transport.events.channels.resolve_channel` reads either form).
"""

from __future__ import annotations

import contextlib
import threading
import time
from struct import error as StructError
from typing import Any

import MiroNaming
import zmq

from miro_gen.corba.ior import TAG_MIRO_ZMQ, Profile
from miro_gen.corba.notify import ChannelCore, EventChannelFactory, EventType, NotifyChannel
from miro_gen.corba.notify.admins import Maker
from miro_gen.corba.notify.wire import EVENT_CHANNEL, EVENT_CHANNEL_FACTORY
from miro_gen.corba.server import IIOPServer
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime import registry
from miro_gen.runtime.cdrstream import encapsulated
from miro_gen.runtime.rpc import Invoker
from miro_gen.transport import shm, sockets
from miro_gen.transport.events.channels import EventChannel
from miro_gen.transport.events.frames import (
    BATCH_HEADER,
    EVENT,
    EVENT_HEADER,
    FrameError,
    read_batch_head,
    split_topic,
    topic,
)
from miro_gen.transport.events.supplier import StructuredPushSupplier

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)

JOIN_WAIT = 0.5  # seconds a new supplier of the door waits to learn the channel's subscriptions
MAX_DOMAINS = 16  # domains one CORBA supplier may publish in (a supplier of the door each)
MAX_SEEN = 4096  # event types seen coming from the ZeroMQ door (its offers)
_TURN_FRAMES = 256


class RawPayload:
    """A generated type's CDR, pushed as it is (what `StructuredPushSupplier` asks of a
    payload: its type's hash and name, its bytes)."""

    __slots__ = ("_type_hash", "_type_name", "data")

    def __init__(self, cls: type, data: bytes) -> None:
        self._type_hash: str = cls._type_hash  # type: ignore[attr-defined]
        self._type_name: str = getattr(cls, "_type_name", cls.__name__)
        self.data = data

    def serialize(self) -> bytes:
        return self.data

    def _encode(self, buf: bytearray) -> None:
        buf += memoryview(self.data)[4:]  # after the header the encoder wrote


def own_prefix(t: EventType) -> bytes:
    """What the tap subscribes to for CORBA consumers of `t` (see the module's doc)."""
    if t.domain_name == "*":
        return b""
    if t.type_name == "*":
        return t.domain_name.encode()
    return t.domain_name.encode() + b"\0" + t.type_name.encode()


def prefix_type(prefix: bytes) -> EventType | None:
    """The event type a ZeroMQ consumer's subscription prefix stands for (None: not one a
    consumer of miro-gen makes)."""
    if not prefix:
        return EventType("*", "*")
    parts = prefix.split(b"\0")
    try:
        if len(parts) == 2 and not parts[1]:
            return EventType(parts[0].decode(), "*")
        if len(parts) == 3 and not parts[2]:
            return EventType(parts[0].decode(), parts[1].decode())
    except UnicodeDecodeError:
        return None
    return None


class _Watch:
    """A raw XPUB socket on the channel that only listens to subscriptions: the prefixes that
    someone subscribes to (the channel forwards one subscription per prefix when it is first
    made, and one unsubscription when its last subscriber leaves)."""

    def __init__(self, door: ZmqSide) -> None:
        self.door = door
        self.prefixes: set[bytes] = set()
        context = door.channel.reactor.context
        self.socket: zmq.Socket[Any] = context.socket(zmq.XPUB)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.XPUB_VERBOSER, 1)
        self.socket.connect(door.channel.endpoints(context)[0])
        door.reactor.call_soon(door.reactor.register, self.socket, self._readable)

    def _readable(self) -> None:
        changed = False
        while True:
            try:
                msg = self.socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                break
            if not msg or (msg[0] == 1 and len(self.prefixes) >= 10_000):
                continue
            if msg[0] == 1:
                changed |= msg[1:] not in self.prefixes
                self.prefixes.add(msg[1:])
            else:
                changed |= msg[1:] in self.prefixes
                self.prefixes.discard(msg[1:])
        if changed:
            self.door.others_changed()

    def close(self) -> None:
        self.door.reactor.unregister(self.socket)
        self.socket.close(0)


class _Tap:
    """A raw SUB socket on the channel: the events CORBA consumers subscribe to, handed to the
    hub with their payloads as they came (the door's own skipped)."""

    def __init__(self, door: ZmqSide) -> None:
        self.door = door
        self.prefixes: set[bytes] = set()
        self.received = 0
        self.unknown = 0  # events whose type hash no generated type has
        context = door.channel.reactor.context
        self.socket: zmq.Socket[Any] = context.socket(zmq.SUB)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.RCVHWM, sockets.queue_limit(context))
        self.socket.connect(door.channel.endpoints(context)[1])
        self._unknown: set[str] = set()
        door.reactor.call_soon(door.reactor.register, self.socket, self._readable)

    def subscribe(self, prefixes: set[bytes]) -> None:
        """Subscribe to exactly `prefixes` (on the reactor thread)."""
        framed = shm.framed_marker()  # it reads no shared memory: large events in frames
        for p in self.prefixes - prefixes:
            self.socket.setsockopt(zmq.UNSUBSCRIBE, p)
            self.socket.setsockopt(zmq.UNSUBSCRIBE, framed + p)
        for p in prefixes - self.prefixes:
            self.socket.setsockopt(zmq.SUBSCRIBE, p)
            self.socket.setsockopt(zmq.SUBSCRIBE, framed + p)
        self.prefixes = prefixes
        self.door.forget_wanted()

    def _readable(self) -> None:
        for _ in range(_TURN_FRAMES):
            try:
                parts = self.socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            try:
                self._frame(parts)
            except (FrameError, StructError, ValueError) as e:
                _peer_warnings.warning("%s: dropped an event frame: %s", self.door.name, e)
        self.door.reactor.call_soon(self._readable)  # more may wait: the rest next turn

    def _frame(self, parts: list[bytes]) -> None:
        if len(parts) != 2:
            raise FrameError(f"{len(parts)} frames, expected 2")
        domain, type_name = split_topic(parts[0])
        body = parts[1]
        count, supplier, raw_hash = read_batch_head(body)
        if supplier in self.door.own:
            return
        self.door.seen(domain, type_name)
        type_hash = raw_hash.hex()
        cls = registry.lookup(type_hash)
        if cls is None:
            self.unknown += count
            if type_hash not in self._unknown and len(self._unknown) < 1000:
                self._unknown.add(type_hash)
                _peer_warnings.warning(
                    "%s: events %s/%s have type hash %s, which no generated type here has: "
                    "not passed to CORBA consumers", self.door.name, domain, type_name,
                    type_hash[:12],
                )  # fmt: skip
            return
        at = BATCH_HEADER
        for _ in range(count):
            _, _, _, n = EVENT.unpack_from(body, at)
            at += EVENT_HEADER
            if at + n > len(body):
                raise FrameError("event payload is truncated")
            self.received += 1
            self.door.hub_in(domain, type_name, cls, body[at : at + n])
            at += n

    def close(self) -> None:
        self.door.reactor.unregister(self.socket)
        self.socket.close(0)


class ZmqSide:
    """The ZeroMQ door of `channel` (hosted in this process) as the hub's `Backbone`."""

    def __init__(self, channel: EventChannel) -> None:
        self.channel = channel
        self.name = channel.name
        self.reactor = channel.reactor
        self.notify: NotifyChannel | None = None
        self.own: set[int] = set()  # supplier ids of the door's suppliers
        self._suppliers: dict[tuple[int, str], StructuredPushSupplier] = {}
        self._seen: set[EventType] = set()
        self._wanted: dict[tuple[str, str], bool] = {}  # topics ZeroMQ consumers want, known
        self._lock = threading.Lock()
        self._watch = _Watch(self)
        self._tap = _Tap(self)
        self._closed = False

    # ---- Backbone ---------------------------------------------------------------------------

    def wants(self, domain: str, type_name: str) -> bool:
        key = (domain, type_name)
        wanted = self._wanted.get(key)
        if wanted is None:
            frame, mine = topic(domain, type_name), self._tap.prefixes
            # A prefix both the tap and others subscribe to, only "", counts: anyone's.
            wanted = any(
                frame.startswith(p) and (p not in mine or not p) for p in list(self._watch.prefixes)
            )
            if len(self._wanted) >= MAX_SEEN:
                self._wanted = {}
            self._wanted[key] = wanted
        return wanted

    def publish(self, source: int, domain: str, type_name: str, cls: type, payload: bytes) -> None:
        supplier = self._suppliers.get((source, domain))
        if supplier is None:
            supplier = self._supplier(source, domain)
            if supplier is None:
                return
            self._join(supplier, type_name)  # just made: it learns the subscriptions first
        supplier.push(type_name, RawPayload(cls, payload))

    def release(self, source: int) -> None:
        with self._lock:
            gone = [k for k in self._suppliers if k[0] == source]
            suppliers = [self._suppliers.pop(k) for k in gone]
        for s in suppliers:
            self.own.discard(s.supplier_id)
            s.close()

    def want(self, types: frozenset[EventType]) -> None:
        prefixes = {own_prefix(t) for t in types}
        if not self._closed:
            self.reactor.call_soon(self._tap.subscribe, prefixes)

    def subscriptions(self) -> frozenset[EventType]:
        found = (prefix_type(p) for p in list(self._watch.prefixes))
        return frozenset(t for t in found if t is not None)

    def offers(self) -> frozenset[EventType]:
        return frozenset(self._seen)

    # ---- the tap and the watch --------------------------------------------------------------

    def hub_in(self, domain: str, type_name: str, cls: type, payload: bytes) -> None:
        if self.notify is not None:
            self.notify.hub.from_backbone(domain, type_name, cls, payload)

    def seen(self, domain: str, type_name: str) -> None:
        t = EventType(domain, type_name)
        if t not in self._seen and len(self._seen) < MAX_SEEN:
            self._seen.add(t)
            if self.notify is not None:
                self.notify.hub.offers_changed()

    def forget_wanted(self) -> None:
        """The subscriptions changed: which topics are wanted is worked out anew."""
        self._wanted = {}

    def others_changed(self) -> None:
        self._wanted = {}
        if self.notify is not None:
            self.notify.hub.others_changed()

    # ---- internals --------------------------------------------------------------------------

    def _supplier(self, source: int, domain: str) -> StructuredPushSupplier | None:
        with self._lock:
            if sum(1 for k in self._suppliers if k[0] == source) >= MAX_DOMAINS:
                _peer_warnings.warning(
                    "%s: a CORBA supplier publishes in more than %d domains: the others are not "
                    "published to ZeroMQ consumers", self.name, MAX_DOMAINS,
                )  # fmt: skip
                return None
            supplier = StructuredPushSupplier(self.channel, domain)
            self.own.add(supplier.supplier_id)
            self._suppliers[(source, domain)] = supplier
        return supplier

    def _join(self, supplier: StructuredPushSupplier, type_name: str) -> None:
        """Wait (at most JOIN_WAIT) for a new supplier to learn that someone subscribes."""
        deadline = time.monotonic() + JOIN_WAIT
        while not supplier.has_subscribers(type_name) and time.monotonic() < deadline:
            time.sleep(0.002)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._lock:
            suppliers = list(self._suppliers.values())
            self._suppliers.clear()
        for s in suppliers:
            s.close()

        def close_sockets() -> None:
            self._tap.close()
            self._watch.close()

        if self.reactor.closed:
            return
        self.reactor.call_soon(close_sockets)


def zmq_profile(channel: EventChannel) -> Profile:
    """The miro-gen profile of the channel's reference: where its ZeroMQ door is."""
    out = encapsulated()
    out.string(channel.supplier_endpoint)
    out.octets(channel.consumer_endpoint.encode())
    return Profile(TAG_MIRO_ZMQ, out.getvalue())


FACTORY_KEY = "NotifyEventChannelFactory"  # the object key, and the name TAO binds it as


def serve_factory(server: IIOPServer, maker: Maker | None = None) -> EventChannelFactory:
    """The EventChannelFactory of this process's channels, served by `server` (`maker`: how to
    make more, else `create_channel` raises NO_IMPLEMENT)."""
    factory = EventChannelFactory(
        lambda: server.ior(FACTORY_KEY.encode(), EVENT_CHANNEL_FACTORY), maker
    )
    server.activate(factory, FACTORY_KEY)
    return factory


class NotifyDoor:
    """The Notification door of `channel`, served by `server` under the key `key` (its full
    name), calling its clients through `invoker`, listed by `factory`."""

    def __init__(
        self,
        channel: EventChannel,
        server: IIOPServer,
        invoker: Invoker,
        key: str,
        factory: EventChannelFactory | None = None,
    ) -> None:
        self.channel = channel
        self.zmq = ZmqSide(channel)
        core = ChannelCore(
            channel.name, server, invoker, key.encode(), self.zmq, [zmq_profile(channel)]
        )
        self.notify = NotifyChannel(core)
        self.zmq.notify = self.notify
        if factory is not None:
            factory.add(self.notify)

    def entry(self) -> MiroNaming.Entry:
        """The naming entry of the channel with both its doors."""
        ior = self.notify.reference()
        return MiroNaming.Entry(self.channel.name, EVENT_CHANNEL, ior.to_string(), b"", "")

    def close(self) -> None:
        self.notify.close()
        with contextlib.suppress(Exception):  # the reactor may be gone
            self.zmq.close()
