"""A notification channel's objects above its proxies: the consumer and supplier admins, the
channel itself (CosNotifyChannelAdmin::EventChannel, which is a CosEventChannelAdmin one too),
and the factory of channels.

Miro's suppliers and consumers each make an admin of their own (`new_for_suppliers(OR_OP)`,
`new_for_consumers(OR_OP)`), set their offers or subscriptions on it, and obtain one proxy from
it; tools list the admins and proxies (`get_all_*admins`, `push_consumers`, `push_suppliers`).
Admin 0 of each kind is the channel's default. The number of admins and proxies is bounded
(core.py).
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable
from typing import ClassVar

from miro_gen.corba.ior import IOR
from miro_gen.corba.notify import wire
from miro_gen.corba.notify.core import MAX_ADMINS, ChannelCore
from miro_gen.corba.notify.filters import FilterAdmin, FilterList
from miro_gen.corba.notify.proxies import (
    Proxy,
    ProxyConsumer,
    ProxyPushConsumer,
    ProxyPushSupplier,
    ProxySupplier,
    StructuredProxyPushConsumer,
    StructuredProxyPushSupplier,
    apply_changes,
)
from miro_gen.corba.notify.qos import QoSAdmin, Settings, as_properties, checked_admin, checked_qos
from miro_gen.corba.notify.wire import (
    EVERYTHING,
    AdminNotFound,
    ChannelNotFound,
    EventType,
    ProxyNotFound,
    read_properties,
    write_properties,
)
from miro_gen.corba.servants import HandServant
from miro_gen.exceptions import NO_IMPLEMENT, NO_PERMISSION, NO_RESOURCES
from miro_gen.log import logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

_log = logger("MIRO")


def _ior_out(ior: IOR, ident: int | None = None) -> CdrOutput:
    out = CdrOutput()
    ior.write(out)
    if ident is not None:
        out.long(ident)
    return out


def _ids_out(ids: list[int]) -> CdrOutput:
    out = CdrOutput()
    out.ulong(len(ids))
    for i in ids:
        out.long(i)
    return out


class _Admin(QoSAdmin, FilterAdmin):
    """What both kinds of admin have."""

    _operations: ClassVar[tuple[str, ...]] = (
        "_get_MyID",
        "_get_MyChannel",
        "_get_MyOperator",
        "destroy",
    )
    prefix = "A"

    def __init__(self, channel: NotifyChannel, ident: int, operator: int) -> None:
        self.channel = channel
        self.core = channel.core
        self.ident = ident
        self.suffix = f"{self.prefix}{ident}"
        self.operator = operator
        self.qos: Settings = {}
        self.filters = FilterList(self.core.filter_factory)
        self.types: set[EventType] = set()
        self.proxies: dict[int, Proxy] = {}
        self.lock = threading.Lock()

    def reference(self) -> IOR:
        return self.core.ior(self.suffix, self._repo_id)

    def proxy_gone(self, proxy: Proxy) -> None:
        with self.lock:
            self.proxies.pop(proxy.ident, None)

    def _new_proxy(self, ctype: int, kinds: dict[int, type[Proxy]]) -> CdrOutput:
        cls = kinds.get(ctype)
        if cls is None:
            raise NO_IMPLEMENT("sequence events are not supported: STRUCTURED_EVENT or ANY_EVENT")
        self.core.take("proxy")
        ident = next(self.core.ids)
        proxy = cls(self, ident)
        with self.lock:
            self.proxies[ident] = proxy
        return _ior_out(self.core.activate(proxy, proxy.suffix), ident)

    def _proxy(self, inp: CdrInput) -> CdrOutput:
        proxy = self.proxies.get(inp.long())
        if proxy is None:
            raise ProxyNotFound()
        return _ior_out(proxy.reference())

    def _ids(self, kind: type[Proxy]) -> CdrOutput:
        return _ids_out(sorted(i for i, p in list(self.proxies.items()) if isinstance(p, kind)))

    def close(self) -> None:
        """Disconnect every proxy and stop serving this admin."""
        for proxy in list(self.proxies.values()):
            if isinstance(proxy, ProxySupplier | ProxyConsumer):
                proxy.disconnect()
        self.core.deactivate(self.suffix)

    @rpc.nonblocking
    def _get_MyID(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.long(self.ident)
        return out

    @rpc.nonblocking
    def _get_MyChannel(self, inp: CdrInput) -> CdrOutput:
        return _ior_out(self.channel.reference())

    @rpc.nonblocking
    def _get_MyOperator(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.ulong(self.operator)
        return out

    @rpc.nonblocking
    def destroy(self, inp: CdrInput) -> None:
        if self.ident == 0:
            return  # the default admin lives as long as its channel
        self.channel.forget_admin(self)
        self.close()


class ConsumerAdmin(_Admin):
    _repo_id = wire.CONSUMER_ADMIN
    _interfaces = frozenset(
        {
            wire.CONSUMER_ADMIN,
            wire.QOS_ADMIN,
            wire.NOTIFY_SUBSCRIBE,
            wire.FILTER_ADMIN,
            wire.COS_CONSUMER_ADMIN,
        }
    )
    _operations: ClassVar[tuple[str, ...]] = (
        "_get_priority_filter",
        "_set_priority_filter",
        "_get_lifetime_filter",
        "_set_lifetime_filter",
        "_get_pull_suppliers",
        "_get_push_suppliers",
        "get_proxy_supplier",
        "obtain_notification_pull_supplier",
        "obtain_notification_push_supplier",
        "subscription_change",
        "obtain_push_supplier",
        "obtain_pull_supplier",
    )
    prefix = "CA"
    _KINDS: dict[int, type[Proxy]] = {
        wire.STRUCTURED_EVENT: StructuredProxyPushSupplier,
        wire.ANY_EVENT: ProxyPushSupplier,
    }

    def __init__(self, channel: NotifyChannel, ident: int, operator: int) -> None:
        super().__init__(channel, ident, operator)
        self.types = {EVERYTHING}  # subscriptions: everything until said otherwise

    _get_priority_filter = ProxySupplier._get_priority_filter
    _get_lifetime_filter = ProxySupplier._get_lifetime_filter
    _set_priority_filter = ProxySupplier._set_priority_filter
    _set_lifetime_filter = ProxySupplier._set_lifetime_filter

    @rpc.nonblocking
    def _get_pull_suppliers(self, inp: CdrInput) -> CdrOutput:
        return _ids_out([])

    @rpc.nonblocking
    def _get_push_suppliers(self, inp: CdrInput) -> CdrOutput:
        return self._ids(ProxySupplier)

    @rpc.nonblocking
    def get_proxy_supplier(self, inp: CdrInput) -> CdrOutput:
        return self._proxy(inp)

    def obtain_notification_pull_supplier(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("pull consumers are not supported: use a push consumer")

    obtain_pull_supplier = obtain_notification_pull_supplier

    @rpc.nonblocking
    def obtain_notification_push_supplier(self, inp: CdrInput) -> CdrOutput:
        return self._new_proxy(inp.ulong(), self._KINDS)

    @rpc.nonblocking
    def obtain_push_supplier(self, inp: CdrInput) -> CdrOutput:
        out = self._new_proxy(wire.ANY_EVENT, self._KINDS)
        del out.buf[-4:]  # CosEventChannelAdmin's operation has no out parameter
        return out

    @rpc.nonblocking
    def subscription_change(self, inp: CdrInput) -> None:
        with self.lock:
            added, removed = apply_changes(self.types, inp)
            proxies = list(self.proxies.values())
        for proxy in proxies:
            if isinstance(proxy, ProxySupplier):
                proxy.admin_changed(added, removed)
        self.core.hub.subscriptions_changed()


class SupplierAdmin(_Admin):
    _repo_id = wire.SUPPLIER_ADMIN
    _interfaces = frozenset(
        {
            wire.SUPPLIER_ADMIN,
            wire.QOS_ADMIN,
            wire.NOTIFY_PUBLISH,
            wire.FILTER_ADMIN,
            wire.COS_SUPPLIER_ADMIN,
        }
    )
    _operations: ClassVar[tuple[str, ...]] = (
        "_get_pull_consumers",
        "_get_push_consumers",
        "get_proxy_consumer",
        "obtain_notification_pull_consumer",
        "obtain_notification_push_consumer",
        "offer_change",
        "obtain_push_consumer",
        "obtain_pull_consumer",
    )
    prefix = "SA"
    _KINDS: dict[int, type[Proxy]] = {
        wire.STRUCTURED_EVENT: StructuredProxyPushConsumer,
        wire.ANY_EVENT: ProxyPushConsumer,
    }

    @rpc.nonblocking
    def _get_pull_consumers(self, inp: CdrInput) -> CdrOutput:
        return _ids_out([])

    @rpc.nonblocking
    def _get_push_consumers(self, inp: CdrInput) -> CdrOutput:
        return self._ids(ProxyConsumer)

    @rpc.nonblocking
    def get_proxy_consumer(self, inp: CdrInput) -> CdrOutput:
        return self._proxy(inp)

    def obtain_notification_pull_consumer(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("pull suppliers are not supported: use a push supplier")

    obtain_pull_consumer = obtain_notification_pull_consumer

    @rpc.nonblocking
    def obtain_notification_push_consumer(self, inp: CdrInput) -> CdrOutput:
        return self._new_proxy(inp.ulong(), self._KINDS)

    @rpc.nonblocking
    def obtain_push_consumer(self, inp: CdrInput) -> CdrOutput:
        out = self._new_proxy(wire.ANY_EVENT, self._KINDS)
        del out.buf[-4:]
        return out

    @rpc.nonblocking
    def offer_change(self, inp: CdrInput) -> None:
        with self.lock:
            added, removed = apply_changes(self.types, inp)
            proxies = list(self.proxies.values())
        for proxy in proxies:
            with proxy.lock:
                proxy.types.difference_update(removed)
                proxy.types.update(added)
        self.core.hub.offers_changed()


class EventChannel(QoSAdmin):
    """The channel's own object (CosNotifyChannelAdmin::EventChannel)."""

    _repo_id = wire.EVENT_CHANNEL
    _interfaces = frozenset({wire.QOS_ADMIN, wire.ADMIN_PROPERTIES_ADMIN, wire.COS_EVENT_CHANNEL})
    _operations: ClassVar[tuple[str, ...]] = (
        "_get_MyFactory",
        "_get_default_consumer_admin",
        "_get_default_supplier_admin",
        "_get_default_filter_factory",
        "new_for_consumers",
        "new_for_suppliers",
        "get_consumeradmin",
        "get_supplieradmin",
        "get_all_consumeradmins",
        "get_all_supplieradmins",
        "get_admin",
        "set_admin",
        "for_consumers",
        "for_suppliers",
        "destroy",
    )

    def __init__(self, channel: NotifyChannel) -> None:
        self.channel = channel
        self.core = channel.core

    @property
    def qos(self) -> Settings:
        return self.core.qos

    @qos.setter
    def qos(self, settings: Settings) -> None:
        self.core.qos = settings

    @rpc.nonblocking
    def _get_MyFactory(self, inp: CdrInput) -> CdrOutput:
        factory = self.channel.factory
        return _ior_out(factory.reference() if factory is not None else IOR())

    @rpc.nonblocking
    def _get_default_consumer_admin(self, inp: CdrInput) -> CdrOutput:
        return _ior_out(self.channel.consumer_admins[0].reference())

    @rpc.nonblocking
    def _get_default_supplier_admin(self, inp: CdrInput) -> CdrOutput:
        return _ior_out(self.channel.supplier_admins[0].reference())

    for_consumers = _get_default_consumer_admin
    for_suppliers = _get_default_supplier_admin

    @rpc.nonblocking
    def _get_default_filter_factory(self, inp: CdrInput) -> CdrOutput:
        return _ior_out(self.core.ior("FF", wire.FILTER_FACTORY))

    @rpc.nonblocking
    def new_for_consumers(self, inp: CdrInput) -> CdrOutput:
        admin = self.channel.new_admin(ConsumerAdmin, inp.ulong())
        return _ior_out(admin.reference(), admin.ident)

    @rpc.nonblocking
    def new_for_suppliers(self, inp: CdrInput) -> CdrOutput:
        admin = self.channel.new_admin(SupplierAdmin, inp.ulong())
        return _ior_out(admin.reference(), admin.ident)

    @rpc.nonblocking
    def get_consumeradmin(self, inp: CdrInput) -> CdrOutput:
        admin = self.channel.consumer_admins.get(inp.long())
        if admin is None:
            raise AdminNotFound()
        return _ior_out(admin.reference())

    @rpc.nonblocking
    def get_supplieradmin(self, inp: CdrInput) -> CdrOutput:
        admin = self.channel.supplier_admins.get(inp.long())
        if admin is None:
            raise AdminNotFound()
        return _ior_out(admin.reference())

    @rpc.nonblocking
    def get_all_consumeradmins(self, inp: CdrInput) -> CdrOutput:
        return _ids_out(sorted(self.channel.consumer_admins))

    @rpc.nonblocking
    def get_all_supplieradmins(self, inp: CdrInput) -> CdrOutput:
        return _ids_out(sorted(self.channel.supplier_admins))

    @rpc.nonblocking
    def get_admin(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        write_properties(out, as_properties(self.core.admin))
        return out

    @rpc.nonblocking
    def set_admin(self, inp: CdrInput) -> None:
        self.core.admin = {**self.core.admin, **checked_admin(read_properties(inp))}

    @rpc.nonblocking
    def destroy(self, inp: CdrInput) -> None:
        if not self.channel.destroyable:
            raise NO_PERMISSION(
                f"{self.core.name} belongs to the process that hosts it, which destroys it"
            )
        self.channel.close()


class NotifyChannel:
    """A notification channel served over IIOP: its objects, and the hub that joins it to its
    other door (see `ChannelCore` for the arguments)."""

    def __init__(self, core: ChannelCore, *, destroyable: bool = False) -> None:
        self.core = core
        self.hub = core.hub
        self.destroyable = destroyable  # made through the factory: CORBA clients may destroy it
        self.factory: EventChannelFactory | None = None
        self.consumer_admins: dict[int, ConsumerAdmin] = {}
        self.supplier_admins: dict[int, SupplierAdmin] = {}
        self._admin_ids = itertools.count(1)
        self._lock = threading.Lock()
        self.servant = EventChannel(self)
        core.activate(self.servant, "")
        core.activate(core.filter_factory, "FF")
        self.consumer_admins[0] = ConsumerAdmin(self, 0, wire.OR_OP)
        self.supplier_admins[0] = SupplierAdmin(self, 0, wire.OR_OP)
        for admin in (self.consumer_admins[0], self.supplier_admins[0]):
            core.activate(admin, admin.suffix)
        self.on_close: list[Callable[[], object]] = []

    def reference(self) -> IOR:
        return self.core.ior("", wire.EVENT_CHANNEL)

    def new_admin(self, kind: type[ConsumerAdmin] | type[SupplierAdmin], operator: int) -> _Admin:
        admins: dict[int, ConsumerAdmin] | dict[int, SupplierAdmin]
        admins = self.consumer_admins if kind is ConsumerAdmin else self.supplier_admins
        with self._lock:
            if len(admins) >= MAX_ADMINS:
                raise NO_RESOURCES(f"{self.core.name} has {MAX_ADMINS} admins of that kind")
            admin = kind(self, next(self._admin_ids), operator)
            admins[admin.ident] = admin  # type: ignore[assignment]
        self.core.activate(admin, admin.suffix)
        return admin

    def forget_admin(self, admin: _Admin) -> None:
        with self._lock:
            if isinstance(admin, ConsumerAdmin):
                self.consumer_admins.pop(admin.ident, None)
            else:
                self.supplier_admins.pop(admin.ident, None)

    def close(self) -> None:
        """Stop serving the channel: every proxy disconnected, every object deactivated."""
        with self.core.lock:
            if self.core.closed:
                return
            self.core.closed = True
        for admin in [*self.consumer_admins.values(), *self.supplier_admins.values()]:
            admin.close()
        self.core.deactivate("FF")
        self.core.deactivate("")
        self.core.notifier.close()
        for fn in self.on_close:
            fn()


Maker = Callable[[Settings, Settings], NotifyChannel]


class EventChannelFactory(HandServant):
    """The factory of a process's notification channels (CosNotifyChannelAdmin's
    EventChannelFactory): the channels the process hosts, and `create_channel` for more when
    the process can make them (`maker`; else NO_IMPLEMENT)."""

    _repo_id = wire.EVENT_CHANNEL_FACTORY
    _interfaces = frozenset()
    _operations: ClassVar[tuple[str, ...]] = (
        "create_channel",
        "get_all_channels",
        "get_event_channel",
    )
    MAX_CHANNELS = 64

    def __init__(self, reference: Callable[[], IOR], maker: Maker | None = None) -> None:
        self.reference = reference
        self.maker = maker
        self.channels: dict[int, NotifyChannel] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    def add(self, channel: NotifyChannel) -> int:
        """List `channel` (once); its id."""
        with self._lock:
            for known, c in self.channels.items():
                if c is channel:
                    return known
            ident = next(self._ids)
            self.channels[ident] = channel
        channel.factory = self
        channel.on_close.append(lambda: self.channels.pop(ident, None))
        return ident

    def create_channel(self, inp: CdrInput) -> CdrOutput:
        qos, admin = checked_qos(read_properties(inp)), checked_admin(read_properties(inp))
        if self.maker is None:
            raise NO_IMPLEMENT("this process makes no further channels")
        if len(self.channels) >= self.MAX_CHANNELS:
            raise NO_RESOURCES(f"at most {self.MAX_CHANNELS} channels")
        channel = self.maker(qos, admin)
        ident = self.add(channel)
        return _ior_out(channel.reference(), ident)

    @rpc.nonblocking
    def get_all_channels(self, inp: CdrInput) -> CdrOutput:
        return _ids_out(sorted(self.channels))

    @rpc.nonblocking
    def get_event_channel(self, inp: CdrInput) -> CdrOutput:
        channel = self.channels.get(inp.long())
        if channel is None:
            raise ChannelNotFound()
        return _ior_out(channel.reference())
