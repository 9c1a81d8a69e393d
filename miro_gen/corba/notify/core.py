"""What every object of one notification channel shares: its hub, the IIOP server that serves
its objects under keys of its own, the invoker that calls its clients back, its QoS and admin
properties, its filter factory, the notifier that tells suppliers of subscription changes, and
the limits on what its clients may make.

Object keys are the channel's key and a suffix (`robot1/EventChannel#CA1/P3`): with a fixed
IIOP port, the channel's reference stays the same across restarts of its process.
"""

from __future__ import annotations

import itertools
import threading
from typing import Any

from miro_gen.corba.ior import IOR, Profile
from miro_gen.corba.notify.delivery import Notifier
from miro_gen.corba.notify.filters import Activator, FilterFactory
from miro_gen.corba.notify.hub import Backbone, Hub
from miro_gen.corba.notify.qos import Settings
from miro_gen.corba.notify.wire import AdminLimitExceeded
from miro_gen.corba.server import IIOPServer
from miro_gen.exceptions import NO_RESOURCES
from miro_gen.runtime import rpc

MAX_ADMINS = 1000  # consumer and supplier admins of a channel, each
MAX_CONSUMERS = 256  # push consumers connected to a channel (a thread each)
MAX_SUPPLIERS = 1024  # proxies for suppliers of a channel
MAX_PROXIES = 4096  # proxies of a channel, connected or not


class ChannelCore(Activator):
    """The shared state of channel `name`, whose objects `server` serves under `key`."""

    def __init__(
        self,
        name: str,
        server: IIOPServer,
        invoker: Any,
        key: bytes,
        backbone: Backbone | None = None,
        profiles: list[Profile] | None = None,
    ) -> None:
        self.name = name
        self.server = server
        self.invoker = invoker
        self.key = key
        self.profiles = profiles or []  # the channel's reference's other profiles (ZeroMQ's)
        self.hub = Hub(name, backbone)
        self.qos: Settings = {}
        self.admin: Settings = {}
        self.filter_factory = FilterFactory(self)
        self.notifier = Notifier(invoker, "subscription_change", f"miro-notify-{name}")
        self.hub.on_subscriptions.append(self.notifier.poke)
        self.ids = itertools.count(1)
        self.consumers = 0  # push consumers connected
        self.suppliers = 0  # supplier proxies
        self.proxies = 0
        self.lock = threading.Lock()
        self.closed = False

    # ---- objects ----------------------------------------------------------------------------

    def object_key(self, suffix: str) -> bytes:
        return self.key + b"#" + suffix.encode() if suffix else self.key

    def ior(self, suffix: str, repo_id: str) -> IOR:
        ior = self.server.ior(self.object_key(suffix), repo_id)
        if not suffix and self.profiles:
            ior = IOR(ior.type_id, [*ior.profiles, *self.profiles])
        return ior

    def activate(self, servant: rpc.Servant, suffix: str) -> IOR:
        self.server.activate(servant, self.object_key(suffix))
        return self.ior(suffix, servant._repo_id)

    def deactivate(self, suffix: str) -> None:
        self.server.deactivate(self.object_key(suffix))

    # ---- limits -----------------------------------------------------------------------------

    def take(self, what: str) -> None:
        """Room for one more proxy (`what`: "consumer" connecting, "supplier", "proxy");
        AdminLimitExceeded (the admin property's name and value) when there is none."""
        with self.lock:
            if what == "consumer":
                limit = min(MAX_CONSUMERS, self.admin.get("MaxConsumers") or MAX_CONSUMERS)
                if self.consumers >= limit:
                    raise AdminLimitExceeded("MaxConsumers", limit)
                self.consumers += 1
            elif what == "supplier":
                limit = min(MAX_SUPPLIERS, self.admin.get("MaxSuppliers") or MAX_SUPPLIERS)
                if self.suppliers >= limit:
                    raise AdminLimitExceeded("MaxSuppliers", limit)
                self.suppliers += 1
            else:
                if self.proxies >= MAX_PROXIES:
                    raise NO_RESOURCES(f"{self.name} has {MAX_PROXIES} proxies already")
                self.proxies += 1

    def give(self, what: str) -> None:
        with self.lock:
            if what == "consumer":
                self.consumers -= 1
            elif what == "supplier":
                self.suppliers -= 1
            else:
                self.proxies -= 1
