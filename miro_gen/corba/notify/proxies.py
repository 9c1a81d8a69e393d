"""The proxies of a notification channel: what its suppliers push into (proxy consumers) and
what pushes to its consumers (proxy suppliers), for structured events and plain `any`s.

A proxy starts with its admin's event types (a consumer's subscriptions: everything, `*`/`*`,
until changed; a supplier's offers: none) and follows the admin's changes; its own
`subscription_change` / `offer_change` change it alone. What a proxy supplier pushes passes
its subscriptions, then the filters (its admin's and its own, joined by the admin's
operator, AND_OP or OR_OP; no filters pass everything, as in TAO), then waits in its consumer's
queue (`delivery.Pusher`). A proxy consumer's filters decide what enters the channel.

Disconnecting (by the client, or the channel dropping a consumer found gone) destroys the
proxy. Suppliers learn of subscription changes, consumers of offer changes, unless they asked
for no updates (`obtain_*_types` with an UPDATES_OFF mode).
"""

from __future__ import annotations

import threading
from typing import ClassVar, Protocol

from miro_gen.corba import anys
from miro_gen.corba import typecode as tcm
from miro_gen.corba.ior import IOR, ref_from_ior
from miro_gen.corba.notify import wire
from miro_gen.corba.notify.core import ChannelCore
from miro_gen.corba.notify.delivery import Pusher, Told
from miro_gen.corba.notify.filters import Fields, FilterAdmin, FilterList
from miro_gen.corba.notify.hub import Outgoing
from miro_gen.corba.notify.qos import QoSAdmin, Settings, depth, drops_newest
from miro_gen.corba.notify.wire import (
    ALL_NOW_UPDATES_OFF,
    ALL_NOW_UPDATES_ON,
    AND_OP,
    NONE_NOW_UPDATES_ON,
    AlreadyConnected,
    ConnectionAlreadyActive,
    ConnectionAlreadyInactive,
    Disconnected,
    EventType,
    NotConnected,
    read_event_types,
    write_event_types,
)
from miro_gen.corba.servants import HEADER
from miro_gen.corba.typecode import K
from miro_gen.exceptions import NO_IMPLEMENT
from miro_gen.log import logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

_log = logger("MIRO")


class Admin(Protocol):
    """What a proxy needs of its admin (admins.py)."""

    ident: int
    suffix: str
    core: ChannelCore
    filters: FilterList
    operator: int
    qos: Settings
    types: set[EventType]

    def reference(self) -> IOR: ...

    def proxy_gone(self, proxy: Proxy) -> None: ...


def apply_changes(types: set[EventType], inp: CdrInput) -> tuple[list[EventType], list[EventType]]:
    """Read `added` and `removed`, apply them to `types` (bounded), and return them."""
    added, removed = read_event_types(inp), read_event_types(inp)
    types.difference_update(removed)
    types.update(added)
    if len(types) > wire.MAX_TYPES:
        for t in added:
            types.discard(t)
        raise wire.InvalidEventType(added[0])
    return added, removed


def _types_out(types: frozenset[EventType] | list[EventType]) -> CdrOutput:
    out = CdrOutput()
    write_event_types(out, sorted(types))
    return out


def _nil() -> CdrOutput:
    out = CdrOutput()
    IOR().write(out)
    return out


class Proxy(QoSAdmin, FilterAdmin):
    """What every proxy has: its admin, its number, QoS, filters, and whether connected."""

    _operations: ClassVar[tuple[str, ...]] = ("_get_MyType", "_get_MyAdmin", "validate_event_qos")
    my_type: ClassVar[int] = wire.PUSH_STRUCTURED

    def __init__(self, admin: Admin, ident: int) -> None:
        self.admin = admin
        self.core = admin.core
        self.ident = ident
        self.suffix = f"{admin.suffix}/P{ident}"
        self.name = f"{self.core.name}#{self.suffix}"
        self.qos: Settings = {}
        self.filters = FilterList(self.core.filter_factory)
        self.types = set(admin.types)
        self.connected = False
        self.peer = ObjectRef()
        self.lock = threading.Lock()
        self.destroyed = False

    def reference(self) -> IOR:
        return self.core.ior(self.suffix, self._repo_id)

    def passes(self, fields: Fields) -> bool:
        """Whether an event passes the admin's and this proxy's filters."""
        mine, theirs = self.filters.passes(fields), self.admin.filters.passes(fields)
        return (mine and theirs) if self.admin.operator == AND_OP else (mine or theirs)

    def filtered(self) -> bool:
        return bool(self.filters) or bool(self.admin.filters)

    def destroy(self) -> None:
        with self.lock:
            if self.destroyed:
                return
            self.destroyed = True
        self.core.deactivate(self.suffix)
        self.admin.proxy_gone(self)
        self.core.give("proxy")

    @rpc.nonblocking
    def _get_MyType(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.ulong(self.my_type)
        return out

    @rpc.nonblocking
    def _get_MyAdmin(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        self.admin.reference().write(out)
        return out

    @rpc.nonblocking
    def validate_event_qos(self, inp: CdrInput) -> CdrOutput:
        return self.validate_qos(inp)


# ---- what suppliers push into -------------------------------------------------------------------


class ProxyConsumer(Proxy):
    """A proxy that a supplier pushes into (CosNotifyChannelAdmin::ProxyConsumer)."""

    _interfaces = frozenset(
        {wire.PROXY_CONSUMER, wire.NOTIFY_PUBLISH, wire.QOS_ADMIN, wire.FILTER_ADMIN}
    )
    _operations: ClassVar[tuple[str, ...]] = ("obtain_subscription_types", "offer_change")

    def __init__(self, admin: Admin, ident: int) -> None:
        super().__init__(admin, ident)  # its types: its offers
        self.told = Told()
        self.core.hub.add_supplier(self)

    def offered(self) -> frozenset[EventType]:
        return frozenset(self.types)

    @rpc.nonblocking
    def obtain_subscription_types(self, inp: CdrInput) -> CdrOutput:
        mode = inp.ulong()
        now = self.core.hub.subscriptions()
        self.told.updates = mode in (ALL_NOW_UPDATES_ON, NONE_NOW_UPDATES_ON)
        self.told.types = now
        return _types_out(now if mode in (ALL_NOW_UPDATES_ON, ALL_NOW_UPDATES_OFF) else [])

    @rpc.nonblocking
    def offer_change(self, inp: CdrInput) -> None:
        with self.lock:
            apply_changes(self.types, inp)
        self.core.hub.offers_changed()

    def connect(self, inp: CdrInput, notify: bool) -> None:
        ref = ref_from_ior(IOR.read(inp))
        with self.lock:
            if self.connected:
                raise AlreadyConnected()
            self.connected = True
            self.peer = ref
        if ref and notify:  # a CosNotifyComm supplier: told of subscription changes
            self.core.notifier.watch(self.ident, ref, self.told, self.core.hub.subscriptions)

    def push_event(self, inp: CdrInput) -> None:
        if not self.connected:
            raise Disconnected()
        self.core.hub.from_corba(self.ident, inp, self.passes if self.filtered() else None)

    def disconnect(self) -> None:
        self.core.notifier.forget(self.ident)
        self.core.hub.remove_supplier(self)
        self.connected = False
        self.destroy()


class StructuredProxyPushConsumer(ProxyConsumer):
    _repo_id = wire.STRUCTURED_PROXY_PUSH_CONSUMER
    _interfaces = ProxyConsumer._interfaces | {wire.STRUCTURED_PUSH_CONSUMER}
    _operations: ClassVar[tuple[str, ...]] = (
        "connect_structured_push_supplier",
        "push_structured_event",
        "disconnect_structured_push_consumer",
    )

    @rpc.nonblocking
    def connect_structured_push_supplier(self, inp: CdrInput) -> None:
        self.connect(inp, notify=True)

    @rpc.nonblocking
    def push_structured_event(self, inp: CdrInput) -> None:
        self.push_event(inp)

    @rpc.nonblocking
    def disconnect_structured_push_consumer(self, inp: CdrInput) -> None:
        self.disconnect()


class ProxyPushConsumer(ProxyConsumer):
    """Takes plain `any`s: each enters as a structured event of type `%ANY`, no domain."""

    _repo_id = wire.PROXY_PUSH_CONSUMER
    _interfaces = ProxyConsumer._interfaces | {
        wire.NOTIFY_PUSH_CONSUMER,
        wire.COS_PUSH_CONSUMER,
        wire.COS_PROXY_PUSH_CONSUMER,
    }
    _operations: ClassVar[tuple[str, ...]] = (
        "connect_any_push_supplier",
        "connect_push_supplier",
        "push",
        "disconnect_push_consumer",
    )
    my_type = wire.PUSH_ANY

    @rpc.nonblocking
    def connect_any_push_supplier(self, inp: CdrInput) -> None:
        self.connect(inp, notify=True)

    @rpc.nonblocking
    def connect_push_supplier(self, inp: CdrInput) -> None:
        self.connect(inp, notify=False)  # a CosEventComm supplier: no subscription_change

    @rpc.nonblocking
    def push(self, inp: CdrInput) -> None:
        out = wire.event_prefix("", wire.ANY_TYPE)
        anys.transcode(tcm.simple(K.tk_any), inp, out, anys.GIOP_REFS, anys.GIOP_REFS)
        self.push_event(CdrInput(bytes(out.buf)))

    @rpc.nonblocking
    def disconnect_push_consumer(self, inp: CdrInput) -> None:
        self.disconnect()


# ---- what pushes to consumers -------------------------------------------------------------------


class ProxySupplier(Proxy):
    """A proxy that pushes to a consumer (CosNotifyChannelAdmin::ProxySupplier)."""

    _interfaces = frozenset(
        {wire.PROXY_SUPPLIER, wire.NOTIFY_SUBSCRIBE, wire.QOS_ADMIN, wire.FILTER_ADMIN}
    )
    _operations: ClassVar[tuple[str, ...]] = (
        "obtain_offered_types",
        "subscription_change",
        "_get_priority_filter",
        "_set_priority_filter",
        "_get_lifetime_filter",
        "_set_lifetime_filter",
        "suspend_connection",
        "resume_connection",
    )
    push_operation: ClassVar[str] = "push_structured_event"

    def __init__(self, admin: Admin, ident: int) -> None:
        super().__init__(admin, ident)
        self.pusher: Pusher | None = None
        self.suspended = False
        self.offers_told = Told()
        self.tell_offers = True
        self._subscribed = frozenset(self.types)
        self.core.hub.add_consumer(self)

    # ---- what the hub and the pusher ask --------------------------------------------------

    def subscribed(self) -> frozenset[EventType]:
        return self._subscribed

    def deliver(self, event: Outgoing) -> None:
        pusher = self.pusher
        if pusher is None or self.suspended:
            return
        if self.filtered() and not self.passes(event.fields):
            return
        pusher.put(event)

    def offers_changed(self) -> None:
        if self.pusher is not None and self.tell_offers:
            self.pusher.changed()

    def request(self, event: Outgoing) -> tuple[str, bytes]:
        return self.push_operation, HEADER + event.body

    def pending_change(self) -> bytes | None:
        return self.offers_told.change(self.core.hub.offers()) if self.tell_offers else None

    def gone(self, why: str) -> None:
        _log.notice("%s: dropped its consumer, which %s", self.core.name, why)
        self.disconnect()

    # ---- operations -------------------------------------------------------------------------

    @rpc.nonblocking
    def obtain_offered_types(self, inp: CdrInput) -> CdrOutput:
        mode = inp.ulong()
        now = self.core.hub.offers()
        self.offers_told.updates = mode in (ALL_NOW_UPDATES_ON, NONE_NOW_UPDATES_ON)
        self.offers_told.types = now
        return _types_out(now if mode in (ALL_NOW_UPDATES_ON, ALL_NOW_UPDATES_OFF) else [])

    @rpc.nonblocking
    def subscription_change(self, inp: CdrInput) -> None:
        with self.lock:
            apply_changes(self.types, inp)
            self._subscribed = frozenset(self.types)
        self.core.hub.subscriptions_changed()

    def admin_changed(self, added: list[EventType], removed: list[EventType]) -> None:
        """The admin's subscriptions changed: so do this proxy's (the hub is told after)."""
        with self.lock:
            self.types.difference_update(removed)
            self.types.update(added)
            self._subscribed = frozenset(self.types)

    @rpc.nonblocking
    def _get_priority_filter(self, inp: CdrInput) -> CdrOutput:
        return _nil()

    @rpc.nonblocking
    def _get_lifetime_filter(self, inp: CdrInput) -> CdrOutput:
        return _nil()

    @rpc.nonblocking
    def _set_priority_filter(self, inp: CdrInput) -> None:
        if not IOR.read(inp).is_nil():
            raise NO_IMPLEMENT("mapping filters are not supported")

    _set_lifetime_filter = _set_priority_filter

    @rpc.nonblocking
    def suspend_connection(self, inp: CdrInput) -> None:
        if not self.connected:
            raise NotConnected()
        if self.suspended:
            raise ConnectionAlreadyInactive()
        self.suspended = True

    @rpc.nonblocking
    def resume_connection(self, inp: CdrInput) -> None:
        if not self.connected:
            raise NotConnected()
        if not self.suspended:
            raise ConnectionAlreadyActive()
        self.suspended = False

    def connect(self, inp: CdrInput, tell_offers: bool) -> None:
        ior = IOR.read(inp)
        if ior.is_nil():
            raise wire.TypeError_()  # a push consumer must be given
        with self.lock:
            if self.connected:
                raise AlreadyConnected()
            self.core.take("consumer")
            self.connected = True
        self.peer = ref_from_ior(ior)
        self.tell_offers = tell_offers
        effective = {**self.core.qos, **self.admin.qos, **self.qos}
        self.pusher = Pusher(
            self.core.invoker, self.peer, self, depth(effective), drops_newest(effective)
        )
        self.core.hub.subscriptions_changed()  # now it counts for the other door

    def qos_changed(self) -> None:
        if self.pusher is not None:
            effective = {**self.core.qos, **self.admin.qos, **self.qos}
            self.pusher.resize(depth(effective), drops_newest(effective))

    def disconnect(self) -> None:
        with self.lock:
            was, self.connected = self.connected, False
            pusher, self.pusher = self.pusher, None
        if pusher is not None:
            pusher.close()
        if was:
            self.core.give("consumer")
        self.core.hub.remove_consumer(self)
        self.destroy()


class StructuredProxyPushSupplier(ProxySupplier):
    _repo_id = wire.STRUCTURED_PROXY_PUSH_SUPPLIER
    _interfaces = ProxySupplier._interfaces | {wire.STRUCTURED_PUSH_SUPPLIER}
    _operations: ClassVar[tuple[str, ...]] = (
        "connect_structured_push_consumer",
        "disconnect_structured_push_supplier",
    )

    @rpc.nonblocking
    def connect_structured_push_consumer(self, inp: CdrInput) -> None:
        self.connect(inp, tell_offers=True)

    @rpc.nonblocking
    def disconnect_structured_push_supplier(self, inp: CdrInput) -> None:
        self.disconnect()


class ProxyPushSupplier(ProxySupplier):
    """Pushes plain `any`s: an event that came as one, else the whole structured event."""

    _repo_id = wire.PROXY_PUSH_SUPPLIER
    _interfaces = ProxySupplier._interfaces | {
        wire.NOTIFY_PUSH_SUPPLIER,
        wire.COS_PUSH_SUPPLIER,
        wire.COS_PROXY_PUSH_SUPPLIER,
    }
    _operations: ClassVar[tuple[str, ...]] = (
        "connect_any_push_consumer",
        "connect_push_consumer",
        "disconnect_push_supplier",
    )
    my_type = wire.PUSH_ANY
    push_operation = "push"

    def request(self, event: Outgoing) -> tuple[str, bytes]:
        return self.push_operation, HEADER + event.as_any()

    @rpc.nonblocking
    def connect_any_push_consumer(self, inp: CdrInput) -> None:
        self.connect(inp, tell_offers=True)

    @rpc.nonblocking
    def connect_push_consumer(self, inp: CdrInput) -> None:
        self.connect(inp, tell_offers=False)  # a CosEventComm consumer: no offer_change

    @rpc.nonblocking
    def disconnect_push_supplier(self, inp: CdrInput) -> None:
        self.disconnect()
