"""Finding running services and what they serve, through the naming service and their service
objects (service/introspection.py): the live tools' view of a robot."""

from __future__ import annotations

import concurrent.futures
from dataclasses import dataclass
from typing import Any

import MiroNaming
import MiroService

from miro_gen.exceptions import SystemException
from miro_gen.live.schemas import Compiled, SchemaError, compile_schema, loaded_stub, stub_class
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Stub
from miro_gen.service.introspection import SERVICE_KEY, SERVICES
from miro_gen.service.server import Client
from miro_gen.transport.events import CHANNEL_REPO_ID
from miro_gen.transport.naming.client import NamingClient, list_entries

SERVICE_REPO_ID = MiroService.Service._repo_id
DESCRIBE_TIMEOUT = 3.0  # seconds a service may take to describe itself


class LiveError(Exception):
    """What the user asked for cannot be done (one line, no traceback)."""


@dataclass
class Running:
    """A running service: its entry in the naming service and its description (None when it
    did not answer: `error` says why)."""

    entry: MiroNaming.Entry
    description: MiroService.Description | None
    error: str = ""

    @property
    def name(self) -> str:
        """`context/name` as `miro list` shows it and `miro param` takes it."""
        context, _, rest = self.entry.name.partition(f"/{SERVICES}/")
        return f"{context}/{rest}"


class Robot:
    """The live tools' connection: a Client (the common options in `argv`) and what it finds."""

    def __init__(self, argv: list[str], timeout: float = 10.0) -> None:
        self.client = Client(argv)
        self.timeout = timeout
        naming = self.client.naming
        if not isinstance(naming, NamingClient):  # a CORBA naming service's
            url = self.client.options.naming_url
            self.client.close()
            raise LiveError(
                f"{url} is a CORBA naming service: the live tools need miro's (--naming "
                "tcp://HOST:PORT); `miro nslist` lists a CORBA one"
            )
        self.naming = naming  # miro's own

    @property
    def options(self) -> Any:
        return self.client.options

    def close(self) -> None:
        self.client.close()

    # ---- naming ----------------------------------------------------------------------------------

    def entries(self, prefix: str = "") -> list[MiroNaming.Entry]:
        try:
            return list_entries(self.naming.registry, prefix)
        except SystemException as e:
            raise LiveError(f"the naming service at {self.options.naming}: {e}") from None

    def resolve(self, name: str) -> MiroNaming.Entry:
        try:
            entry: MiroNaming.Entry = self.client.naming.resolve(name)
            return entry
        except MiroNaming.NotFound as e:
            raise LiveError(f"{e.name} is not bound in the naming service") from None
        except MiroNaming.InvalidName:
            raise LiveError(f"{name!r} is not a name") from None
        except SystemException as e:
            raise LiveError(f"the naming service at {self.options.naming}: {e}") from None

    # ---- service objects -------------------------------------------------------------------------

    def service_at(self, endpoint: str, timeout: float = DESCRIBE_TIMEOUT) -> Any:
        ref = ObjectRef(SERVICE_REPO_ID, endpoint, SERVICE_KEY)
        return MiroService.Service(ref, self.client.invoker, timeout=timeout)

    def services(self) -> list[Running]:
        """Every service bound in the naming service, described (in parallel)."""
        found = [
            e
            for e in self.entries()
            if e.repo_id == SERVICE_REPO_ID and f"/{SERVICES}/" in f"/{e.name}"
        ]

        def describe(entry: MiroNaming.Entry) -> Running:
            try:
                service = self.service_at(entry.endpoint, min(self.timeout, DESCRIBE_TIMEOUT))
                return Running(entry, service.describe())
            except SystemException as e:
                return Running(entry, None, str(e))

        if not found:
            return []
        with concurrent.futures.ThreadPoolExecutor(min(len(found), 16)) as pool:
            return list(pool.map(describe, found))

    def offers(self, patterns: list[tuple[str, str]]) -> list[tuple[Running, MiroService.Offer]]:
        """The events the running services publish whose (domain, type) matches one of
        `patterns` (`*` for any part), with the service of each."""
        from miro_gen.eventlog.types import matches

        return [
            (s, o)
            for s in self.services()
            if s.description is not None
            for o in s.description.offers
            if any(matches(p, o.domain, o.type_name) for p in patterns)
        ]

    def data_schema(self, service: Running, type_hash: str) -> str:
        """The data schema of the type `type_hash` as `service` gives it."""
        try:
            return str(self.service_at(service.entry.endpoint).type_schema(type_hash))
        except (MiroService.NotFound, SystemException) as e:
            raise LiveError(f"the type {type_hash[:12]} from {service.name}: {e}") from None

    def service(self, name: str) -> Running:
        """The service `name` (`gps`, `robot1/gps`, or the name of an object it serves)."""
        services = self.services()
        wanted = name.strip("/")
        matches = [s for s in services if wanted in (s.name, s.name.rsplit("/", 1)[-1])]
        if len(matches) > 1:
            names = ", ".join(s.name for s in matches)
            raise LiveError(f"several services are called {name} ({names}): give CONTEXT/NAME")
        if matches:
            return matches[0]
        try:  # an object's name: the service at its endpoint
            entry = self.client.naming.resolve(name)
        except (MiroNaming.NotFound, MiroNaming.InvalidName, SystemException):
            entry = None
        if entry is not None and entry.repo_id != CHANNEL_REPO_ID:
            for s in services:
                if s.entry.endpoint == entry.endpoint:
                    return s
        known = ", ".join(s.name for s in services) or "none"
        raise LiveError(f"no service {name} (running: {known})")

    # ---- objects ---------------------------------------------------------------------------------

    def interface(self, entry: MiroNaming.Entry) -> Compiled:
        """The interface schema of the object bound as `entry`, compiled."""
        try:
            text = self.service_at(entry.endpoint).interface_schema(entry.repo_id)
        except MiroService.NotFound as e:
            raise LiveError(f"{entry.name} has no interface schema: {e.what}") from None
        except SystemException as e:
            raise LiveError(
                f"{entry.name} does not describe its interface ({e}): is it a miro-gen server?"
            ) from None
        try:
            return compile_schema(text)
        except SchemaError as e:
            raise LiveError(f"{entry.name}: {e}") from None

    def stub(self, entry: MiroNaming.Entry) -> tuple[Stub, Compiled]:
        """A stub for the object of `entry` (the class this process has loaded, when it has
        the very interface, else one compiled from the service's schema), and the schema."""
        compiled = self.interface(entry)
        cls = loaded_stub(entry.repo_id, entry.type_hash) if entry.type_hash else None
        if cls is None:
            try:
                cls = stub_class(compiled, entry.repo_id)
            except SchemaError as e:
                raise LiveError(f"{entry.name}: {e}") from None
        ref = ObjectRef(entry.repo_id, entry.endpoint, entry.key)
        return cls(ref, self.client.invoker, timeout=self.timeout), compiled
