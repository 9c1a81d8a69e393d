"""Where a replay's events go (Miro's ChannelManager): each robot's events into that robot's
channel, and the player's clock into a channel of its own.

A log's *domain* is the naming context of the supplier that pushed an event (its robot). A
service of robot D finds its channel as `D/EventChannel`, else `EventChannel` at the root of
the naming service (transport.naming). The modes, for a channel name NAME:

- default: each domain D into the channel a service of D finds; where there is none, the
  player hosts `D/NAME` and binds it (Miro's LogPlayer created and bound one per robot);
- shared (`--shared-channels`, Miro's -shared_ec): only channels that exist; a domain with
  none is not played (said once);
- unified (`--unified-channel`, Miro's -unified_ec): one channel, hosted here and bound as
  `D/NAME` for every domain D, so that every robot's consumers see all the robots' events;
- a NAME that is a path (`lab/EventChannel`): every event into that one channel, found or
  hosted.

This is the player's one door to the transport (with eventlog.replay): the model
(eventlog.player) hands it events and clock states and knows nothing of channels.
"""

from __future__ import annotations

import random
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import MiroLog
import MiroNaming

from miro_gen.eventlog.fileset import Event
from miro_gen.eventlog.player import ClockState
from miro_gen.eventlog.replay import ReplaySupplier
from miro_gen.exceptions import SystemException
from miro_gen.service.log_clock import CLOCK_TYPE
from miro_gen.transport.events import (
    CHANNEL_REPO_ID,
    EventChannel,
    EventChannelFactory,
    StructuredPushSupplier,
)
from miro_gen.transport.events.channels import channel_endpoints

if TYPE_CHECKING:
    from miro_gen.service.server import Server

DEFAULT_NAME = "EventChannel"
CLOCK_CHANNEL = "LogClock"
MODES = ("own", "shared", "unified")


@dataclass
class Route:
    """The channel of one domain: its name, whether this process hosts it, its supplier."""

    domain: str
    channel: str
    hosted: bool
    supplier: ReplaySupplier


class Routes:
    """The channels of a replay's domains (`connect`), and sending into them (`send`)."""

    def __init__(self, server: Server, name: str = DEFAULT_NAME, mode: str = "own") -> None:
        if mode not in MODES:
            raise ValueError(f"mode is one of {', '.join(MODES)}")
        self.server = server
        self.name = name
        self.mode = mode
        self.routes: dict[str, Route] = {}
        self.problems: dict[str, str] = {}  # domain -> why its events are not played
        self.unrouted = 0  # events of domains without a channel
        self._by_channel: dict[str, ReplaySupplier] = {}
        self._unified: EventChannel | None = None
        self._lock = threading.Lock()
        self._replay_ids: dict[tuple[int, int], int] = {}

    # ---- channels -------------------------------------------------------------------------------

    def connect(self, domains: list[str]) -> list[str]:
        """Find or host the channel of each domain not routed yet; what went wrong, one line
        per domain (those domains' events are not played)."""
        said = []
        for domain in domains:
            if domain in self.routes or domain in self.problems:
                continue
            try:
                route = self._route(domain)
            except (MiroNaming.NotFound, MiroNaming.AlreadyBound, MiroNaming.InvalidName) as e:
                self.problems[domain] = _why(domain, self._channel_name(domain), e)
            except SystemException as e:
                self.problems[domain] = f"{domain}: {e}"
            else:
                with self._lock:
                    self.routes[domain] = route
                continue
            said.append(self.problems[domain])
        return said

    def _channel_name(self, domain: str) -> str:
        return self.name if "/" in self.name else f"{domain}/{self.name}"

    def _route(self, domain: str) -> Route:
        name = self._channel_name(domain)
        factory = EventChannelFactory(self.server)
        if self.mode == "unified" and "/" not in self.name:
            if self._find(name, root=False) is not None:
                raise MiroNaming.AlreadyBound()
            if self._unified is None:
                self._unified = factory.create_channel(name)
            else:
                ch = self._unified
                self.server.bind_entry(
                    MiroNaming.Entry(
                        name,
                        CHANNEL_REPO_ID,
                        ch.supplier_endpoint,
                        ch.consumer_endpoint.encode(),
                        "",
                    )
                )
            return Route(domain, name, True, self._supplier(self._unified))
        found = self._find(name, root="/" not in self.name)
        if found is not None:
            return Route(domain, found.name, False, self._supplier(found))
        if self.mode == "shared":
            raise MiroNaming.NotFound(name=name)
        return Route(domain, name, True, self._supplier(factory.create_channel(name)))

    def _find(self, name: str, root: bool) -> EventChannel | None:
        """The channel bound as `name`, else (with `root`) the root's channel of that name:
        where a service of that domain finds its channel."""
        hosted = self.server.hosted_channels.get(name)
        if hosted is not None:
            return hosted
        naming: Any = self.server.naming
        for path in (name, name.rsplit("/", 1)[1]) if root else (name,):
            try:
                registry = getattr(naming, "registry", naming)
                entry = registry.resolve(path)
            except MiroNaming.NotFound:
                continue
            try:  # a ZeroMQ channel's entry, or one bound with its Notification door
                endpoints = channel_endpoints(entry)
            except MiroNaming.NotFound:
                continue
            return self._channel(entry, endpoints)
        return None

    def _channel(self, entry: MiroNaming.Entry, endpoints: tuple[str, str]) -> EventChannel:
        def again() -> EventChannel:
            found = self._find(entry.name, root=False)
            if found is None:
                raise MiroNaming.NotFound(name=entry.name)
            return found

        return EventChannel(
            entry.name,
            *endpoints,
            self.server.reactor(),
            self.server.options.naming_context,
            resolve=again,
        )

    def _supplier(self, channel: EventChannel) -> ReplaySupplier:
        supplier = self._by_channel.get(channel.name)
        if supplier is None:
            supplier = self._by_channel[channel.name] = ReplaySupplier(channel)
        return supplier

    # ---- sending --------------------------------------------------------------------------------

    def send(self, event: Event) -> None:
        """Push one logged event, as recorded, into its domain's channel (any thread)."""
        topic = event.topic
        route = self.routes.get(topic.domain)
        if route is None:
            self.unrouted += 1
            return
        m = event.message
        route.supplier.push_encoded(
            topic.domain,
            topic.type_name,
            topic.type_hash,
            self._replay_id(event),
            m.sequence,
            m.publish_time,
            m.log_time,
            m.data,
        )

    def _replay_id(self, event: Event) -> int:
        """One supplier id per channel of each file, so that consumers count its gaps as they
        were recorded (a random 63-bit number, as a live supplier's)."""
        key = (event.key[1], event.topic.id)
        sid = self._replay_ids.get(key)
        if sid is None:
            sid = self._replay_ids.setdefault(key, random.getrandbits(63))
        return sid

    def subscribed(self, domain: str, type_name: str) -> bool:
        """Whether a consumer of the domain's channel subscribes to this type (tests and
        `--wait-for` wait for it before playing)."""
        route = self.routes.get(domain)
        return route is not None and route.supplier.has_subscribers_for(domain, type_name)

    def channel_of(self, domain: str) -> str | None:
        route = self.routes.get(domain)
        return None if route is None else route.channel


def _why(domain: str, name: str, e: Exception) -> str:
    if isinstance(e, MiroNaming.NotFound):
        return f"{domain}: no channel {name} (the channels that exist are used: not played)"
    if isinstance(e, MiroNaming.AlreadyBound):
        return f"{domain}: {name} is bound by another process: not played into"
    return f"{domain}: {name} is not a valid name: not played"


class ClockPublisher:
    """Publishes the player's clock (MiroLog::Clock events) on a channel hosted here, bound as
    `name` in the player's naming context, for processes on `--clock log`."""

    def __init__(self, server: Server, name: str = CLOCK_CHANNEL) -> None:
        channel = EventChannelFactory(server).create_channel(name)
        self.channel = channel.name
        self.supplier = StructuredPushSupplier(channel)

    def __call__(self, state: ClockState) -> None:
        clock = MiroLog.Clock(state.log_ns, state.rate, state.paused, state.epoch)
        self.supplier.push(CLOCK_TYPE, clock, stamp=state.log_ns / 1e9)
