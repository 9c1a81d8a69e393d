"""The CosNaming door of `miro naming --iiop-endpoint`: CORBA clients (Miro's C++ `Client` and
`Server`, omniORB's `nameclt`) name and find objects in the same table as the ZeroMQ clients,
under the same rules (miro_gen.corba.naming_server serves the CosNaming operations over it).

Every change goes through the naming service's own servant (`naming_service.Registry`), as the
caller it is: its principal is what `caller.caller_of_tcp` makes of its connection (the user
owning the other end of a loopback connection, from the kernel; its host beyond), so a name a
C++ service of user A binds is A's, as are those of A's Python services, and user B can neither
replace nor remove it. A CORBA client states no service or run: its names belong to its
principal as the service `CosNaming`, so that a C++ service may rebind or unbind, on any
connection, what it bound, and cannot take a name that one of the same user's Python services
holds (another service). CosNaming has no leases: the door renews its clients' names itself
until they are unbound (a C++ service that dies leaves them bound, as omniNames does), and takes
up again, at start, those the log of owners kept.
"""

from __future__ import annotations

import MiroNaming

from miro_gen.corba.naming_server import NamingService as CosNamingService
from miro_gen.corba.server import IIOPServer, current_connection
from miro_gen.exceptions import NO_PERMISSION
from miro_gen.log import logger
from miro_gen.transport.naming.service import Registry
from miro_gen.transport.naming.table import MAX_LEASE_MS, check_name
from miro_gen.transport.rpc import caller
from miro_gen.transport.rpc.caller import Caller

_log = logger("MIRO")

SERVICE = "CosNaming"  # the service of every CORBA client's names
RUN = "iiop"  # ... and their run: the same on every connection
OWNER = MiroNaming.Owner(SERVICE, RUN)
RENEW_EVERY = MAX_LEASE_MS / 3000  # seconds between two renewals of CORBA clients' names


class RegistryTable:
    """The naming service's table as a CosNaming service sees it (corba.naming_server's
    `NameTable`), each call made as the IIOP caller it serves."""

    def __init__(self, registry: Registry) -> None:
        self.registry = registry
        self._held: dict[str, set[str]] = {}  # principal -> CORBA names to renew
        for b in registry.table.bindings():  # read back from the log of owners
            if b.holder.service == SERVICE and b.holder.run == RUN:
                self._held.setdefault(b.holder.principal, set()).add(b.entry.name)

    def _caller(self) -> Caller:
        conn = current_connection()
        if conn is None:
            raise NO_PERMISSION("the naming service cannot tell who calls")
        if isinstance(conn.identity, Caller):
            return conn.identity
        addresses = conn.addresses()
        if addresses is None:
            raise NO_PERMISSION("the naming service cannot tell who calls")
        found = caller.caller_of_tcp(*addresses)
        conn.identity = found
        return found

    def _as_caller(self) -> Caller:
        c = self._caller()
        if c.local and not c.verified:
            raise NO_PERMISSION(
                f"could not tell which user of this machine calls from {c.principal}: names "
                "are bound by their owners only"
            )
        return c

    # ---- NameTable -----------------------------------------------------------------------------

    def resolve(self, path: str) -> MiroNaming.Entry | None:
        try:
            return self.registry.resolve(path)
        except (MiroNaming.NotFound, MiroNaming.InvalidName):
            return None

    def bind(self, entry: MiroNaming.Entry, replace: bool) -> None:
        c = self._as_caller()
        with caller.serving(c):
            self.registry.bind_as(entry, OWNER, MAX_LEASE_MS, True)
        self._held.setdefault(c.principal, set()).add(entry.name)

    def unbind(self, path: str) -> bool:
        c = self._as_caller()
        try:
            with caller.serving(c):
                self.registry.unbind_as(path, OWNER)
        except MiroNaming.InvalidName:
            return False
        except MiroNaming.NotFound:
            if self.resolve(path) is not None:
                raise NO_PERMISSION(f"{path} is bound by another owner") from None
            return False
        self._held.get(c.principal, set()).discard(path)
        return True

    def names(self, prefix: str, after: str, how_many: int) -> tuple[list[str], bool]:
        if prefix:
            try:
                check_name(prefix.rstrip("/"))
            except MiroNaming.InvalidName:
                return [], False
        page = self.registry.list_page(prefix, after, how_many)
        return [e.name for e in page.entries], page.more

    # ---- leases ----------------------------------------------------------------------------

    def renew(self, _: object = None) -> None:
        """Renew the names CORBA clients bound (CosNaming has no leases); forget those the
        table no longer holds for them."""
        for principal, names in list(self._held.items()):
            if not names:
                del self._held[principal]
                continue
            with caller.serving(Caller(principal, True)):
                lost = self.registry.renew_as(OWNER, sorted(names), MAX_LEASE_MS)
            names.difference_update(lost)


def serve_cosnaming(registry: Registry, server: IIOPServer) -> RegistryTable:
    """Serve CosNaming over the naming service's table on `server` (key `NameService`): the
    table, whose `renew` is to be called every RENEW_EVERY seconds."""
    table = RegistryTable(registry)
    CosNamingService(table, server)
    table.renew()
    return table
