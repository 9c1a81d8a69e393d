"""Event channels: where suppliers and consumers of a channel connect, the process that hosts
one (an XSUB/XPUB proxy run by libzmq in a thread), and finding one in the naming service
(docs/PROTOCOL.md, "Event channels"). Suppliers and consumers are in transport.events; a
channel makes their links to it (transport.events.links).

A host's sockets are listening sockets of transport.sockets (limits, CURVE, admission); its
queues hold at most PROXY_HWM frames per peer, fewer when the largest message allowed is large
(`sockets.queue_limit`): the queue is the host's memory, and frames may be camera images.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import MiroNaming
import zmq

from miro_gen.log import logger
from miro_gen.transport import sockets
from miro_gen.transport.addresses import Addresses
from miro_gen.transport.events.links import (
    PublishingLink,
    SubscribingLink,
    ZmqPublishing,
    ZmqSubscribing,
)
from miro_gen.transport.local import bind_twin, nearest
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")

CHANNEL_REPO_ID = "IDL:miro-gen/EventChannel:1.0"
DEFAULT_CHANNEL = "EventChannel"
# Frames a channel queues for each of its peers, at most (high-water marks are set once: libzmq
# can stall a pipe whose mark is lowered while it carries messages).
PROXY_HWM = 1_000
SOCKET_BUFFER = 4 << 20  # bytes; Linux caps it at net.core.wmem_max (often 4 MiB, or 208 KiB)


class ChannelLinks(Protocol):
    """A backbone whose channels are names that no process hosts (Zenoh: a channel is its
    keys, transport.zenoh.links): it links suppliers and consumers to a channel by name.
    `endpoint`: what a channel's naming entry carries."""

    @property
    def endpoint(self) -> str: ...

    def publishing(
        self,
        channel: str,
        on_connection: Callable[[bool], object],
        on_subscriptions: Callable[[list[tuple[bool, bytes]]], object],
        hwm: int,
        burst: int,
    ) -> PublishingLink: ...

    def subscribing(
        self, channel: str, on_readable: Callable[[], object], hwm: int, *, keep_all: bool = False
    ) -> SubscribingLink: ...


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
    # Looks the channel up again (in the naming service) when its host has gone: None for a
    # channel at fixed endpoints (one hosted here, or made by hand).
    resolve: Callable[[], EventChannel] | None = field(default=None, repr=False)
    # Over a backbone without channel hosts (Zenoh), what links suppliers and consumers.
    links: ChannelLinks | None = field(default=None, repr=False)

    def endpoints(self, context: zmq.Context[Any]) -> tuple[str, str]:
        """(supplier, consumer) endpoints for sockets of `context`: in the process that hosts
        the channel, in-process ones (ZeroMQ hands frames over without copying them); on its
        host, its ipc:// twins (miro_gen.transport.local); elsewhere the advertised ones."""
        host = self._host
        if host is not None and host.context is context:
            return host.local_endpoints
        return nearest(self.supplier_endpoint), nearest(self.consumer_endpoint)

    def publishing(
        self,
        on_connection: Callable[[bool], object],
        on_subscriptions: Callable[[list[tuple[bool, bytes]]], object],
        hwm: int,
        burst: int,
        *,
        direct: bool = False,
    ) -> PublishingLink:
        """A supplier's link to this channel (transport.events.links), found again when the
        channel moves (when it has a name to be looked up by). `direct`: one that sends on
        the caller's thread (over ZeroMQ; a backbone without channel hosts ignores it)."""
        if self.links is not None:
            return self.links.publishing(self.name, on_connection, on_subscriptions, hwm, burst)
        context = self.reactor.context
        resolve = self.resolve
        return ZmqPublishing(
            self.reactor,
            self.endpoints(context)[0],
            None if resolve is None else lambda: resolve().endpoints(context)[0],
            on_connection,
            on_subscriptions,
            hwm,
            burst,
            direct=direct,
        )

    def subscribing(
        self, on_readable: Callable[[], object], hwm: int, *, keep_all: bool = False
    ) -> SubscribingLink:
        """A consumer's link to this channel (transport.events.links). `keep_all`: for a
        consumer that keeps every event: a backbone that can (Zenoh) carries its events with
        backpressure instead of dropping them; over ZeroMQ its queues hold `hwm` frames
        whatever the largest message allowed."""
        if self.links is not None:
            return self.links.subscribing(self.name, on_readable, hwm, keep_all=keep_all)
        context = self.reactor.context
        resolve = self.resolve
        return ZmqSubscribing(
            self.reactor,
            self.endpoints(context)[1],
            None if resolve is None else lambda: resolve().endpoints(context)[1],
            on_readable,
            hwm,
            keep_all,
        )


class ChannelHost:
    """Runs a channel's XSUB/XPUB proxy in a thread (libzmq's, without the GIL) until closed:
    in the process that creates the channel, or in `miro naming --channel`.

    Besides its TCP endpoints it binds in-process ones, for the suppliers and consumers of its
    own process (ZeroMQ hands their frames over without copying them), and their ipc://
    twins, for those of other processes on its host."""

    def __init__(self, context: zmq.Context[Any], bind_host: str, advertise: str) -> None:
        self.context = context
        self.xsub = sockets.listening_socket(context, zmq.XSUB)
        self.xpub = sockets.listening_socket(context, zmq.XPUB)
        hwm = min(PROXY_HWM, sockets.queue_limit(context))  # frames of up to the maximum size
        for s in (self.xsub, self.xpub):
            s.setsockopt(zmq.SNDHWM, hwm)
            s.setsockopt(zmq.RCVHWM, hwm)
        self.xpub.setsockopt(zmq.XPUB_VERBOSER, 1)  # every (un)subscription reaches suppliers
        # Besides its frames, each consumer's connection queues up to SOCKET_BUFFER bytes in the
        # kernel: a queue in bytes, which holds thousands of small frames for a keep-all
        # consumer whose process is not scheduled for a moment (not one more 8 MiB frame).
        self.xpub.setsockopt(zmq.SNDBUF, SOCKET_BUFFER)
        port_in = self.xsub.bind_to_random_port(f"tcp://{bind_host}")
        port_out = self.xpub.bind_to_random_port(f"tcp://{bind_host}")
        self.supplier_endpoint = f"tcp://{advertise}:{port_in}"
        self.consumer_endpoint = f"tcp://{advertise}:{port_out}"
        bind_twin(self.xsub, self.supplier_endpoint)
        bind_twin(self.xpub, self.consumer_endpoint)
        name = f"inproc://miro-channel-{os.getpid()}-{id(self)}"
        self.local_endpoints = (f"{name}-suppliers", f"{name}-consumers")
        self.xsub.bind(self.local_endpoints[0])
        self.xpub.bind(self.local_endpoints[1])
        self.control = context.socket(zmq.PAIR)
        self.control.bind(name)
        self._peer = context.socket(zmq.PAIR)
        self._peer.connect(name)
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


class ChannelNaming(Protocol):
    """The naming a channel is found in, in the process's naming context (`context`): the miro
    naming service's client or a CORBA naming service's (service.backbone.Naming)."""

    @property
    def context(self) -> str: ...

    def full_name(self, name: str) -> str: ...

    def resolve(self, name: str) -> MiroNaming.Entry: ...


class ChannelDoor(Protocol):
    """Another door of a hosted channel (its Notification door: events.notify_door): the naming
    entry that names the channel with both doors, and its end."""

    def entry(self) -> MiroNaming.Entry: ...

    def close(self) -> None: ...


class ChannelDoors(Protocol):
    """What opens a hosted channel's other doors: a process's IIOP side (service.iiop)."""

    def open_door(self, channel: EventChannel) -> ChannelDoor: ...


class ChannelServer(Protocol):
    """What event channels need of their process's server (service.server.Server): its
    sockets' context and reactor, where it binds and what it advertises, its naming, binding an
    entry under its lease, its clean-up, and its IIOP side if it has one (`corba`), which opens
    a hosted channel's Notification door."""

    @property
    def context(self) -> zmq.Context[Any]: ...

    @property
    def addresses(self) -> Addresses: ...

    @property
    def naming(self) -> ChannelNaming: ...

    @property
    def hosted_channels(self) -> dict[str, EventChannel]: ...

    @property
    def corba(self) -> ChannelDoors | None: ...

    @property
    def channel_links(self) -> ChannelLinks | None:
        """The links of a backbone without channel hosts (None: ZeroMQ's proxies)."""
        ...

    def reactor(self) -> Reactor: ...

    def bind_entry(self, entry: MiroNaming.Entry) -> None: ...

    def on_shutdown(self, fn: Callable[[], object]) -> None: ...


class EventChannelFactory:
    """Creates event channels hosted by `server`'s process and bound in its naming context."""

    def __init__(self, server: ChannelServer) -> None:
        self.server = server
        # The channels this process hosts, whichever factory created them.
        self._channels: dict[str, EventChannel] = server.hosted_channels

    def create_channel(self, name: str = DEFAULT_CHANNEL) -> EventChannel:
        """Host a channel and bind it as `name`; the one already hosted here if there is one."""
        full = self.server.naming.full_name(name)
        if full in self._channels:
            return self._channels[full]
        links = self.server.channel_links
        if links is not None:  # a name only: no process hosts it
            channel = EventChannel(
                full, links.endpoint, "", self.server.reactor(), self.server.naming.context,
                links=links,
            )  # fmt: skip
            self.server.bind_entry(MiroNaming.Entry(full, CHANNEL_REPO_ID, links.endpoint, b"", ""))
            self._channels[full] = channel
            return channel
        # Bound and advertised like the server's objects (miro_gen.transport.addresses).
        addresses = self.server.addresses
        ch_host = ChannelHost(self.server.context, addresses.bind, addresses.advertise)
        channel = EventChannel(
            full,
            ch_host.supplier_endpoint,
            ch_host.consumer_endpoint,
            self.server.reactor(),
            self.server.naming.context,
            ch_host,
        )
        entry = MiroNaming.Entry(
            full, CHANNEL_REPO_ID, ch_host.supplier_endpoint, ch_host.consumer_endpoint.encode(), ""
        )
        self.server.on_shutdown(ch_host.close)
        doors = self.server.corba
        if doors is not None:  # an IIOP side: the Notification door too (events.notify_door)
            door = doors.open_door(channel)
            self.server.on_shutdown(door.close)
            entry = door.entry()
        self.server.bind_entry(entry)
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


def resolve_channel(server: ChannelServer, name: str = DEFAULT_CHANNEL) -> EventChannel:
    """The channel bound as `name` (naming rules as for objects)."""
    links = server.channel_links
    if links is not None and "*" in name:  # a fleet's channel pattern: no entry to look up
        return EventChannel(name, links.endpoint, "", server.reactor(), server.naming.context,
                            links=links)  # fmt: skip
    entry = server.naming.resolve(name)
    if links is not None:
        if entry.repo_id != CHANNEL_REPO_ID:
            raise MiroNaming.NotFound(name=f"{entry.name} (bound, but not an event channel)")
        return EventChannel(
            entry.name, entry.endpoint, "", server.reactor(), server.naming.context, links=links
        )
    supplier, consumer = channel_endpoints(entry)
    return EventChannel(
        entry.name,
        supplier,
        consumer,
        server.reactor(),
        server.naming.context,
        resolve=lambda: resolve_channel(server, entry.name),
    )


def channel_endpoints(entry: MiroNaming.Entry) -> tuple[str, str]:
    """(supplier, consumer) endpoints of a channel's naming entry: a ZeroMQ channel's, or the
    miro-gen profile of a channel bound with its Notification door (events.notify_door)."""
    if entry.repo_id == CHANNEL_REPO_ID:
        return entry.endpoint, bytes(entry.key).decode()
    ior = getattr(getattr(entry, "ref", None), "ior", None)
    if ior is None and entry.endpoint.startswith("IOR:"):
        from miro_gen.corba.ior import IOR, UrlError

        with contextlib.suppress(UrlError):
            ior = IOR.from_string(entry.endpoint)
    found = ior.zmq_profile() if ior is not None else None
    if found is None:
        raise MiroNaming.NotFound(name=f"{entry.name} (bound, but not an event channel)")
    return found[0], bytes(found[1]).decode("utf-8", "replace")
