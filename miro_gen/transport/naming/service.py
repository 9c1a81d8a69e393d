"""The naming service: `MiroNaming::Registry` 2.0 (idl/MiroNaming.idl) served under the key
`NameService` at a well-known endpoint (`tcp://127.0.0.1:2809` by default) and, on Linux, at
an abstract Unix socket beside it (`transport.local.naming_socket`).

Who owns a name is checked here, not taken on the caller's word: the owner of an entry is the
caller's principal (`transport.rpc.caller`: the user of a process on this machine, from the
kernel, over the Unix socket; the host and key of one beyond it) together with the service
it says it is. A process on this machine that asks over TCP cannot be told from any other
user's, so where the Unix socket exists, its calls that need an owner are refused
(NO_PERMISSION) and it is told to come through the socket; reading (`resolve`, `list_page`)
is open to everyone. The table's rules are in `transport.naming.table`, the log that keeps
owners across restarts in `transport.naming.owners_log`; docs/SECURITY.md says why. A backbone
may add its own rule of who binds what (`admit`: the Zenoh backbone's access control per
robot, transport.zenoh.access).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import MiroNaming
import MiroNaming__POA

from miro_gen.exceptions import NO_PERMISSION, NO_RESOURCES
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime.rpc import nonblocking
from miro_gen.transport import sockets
from miro_gen.transport.local import naming_socket
from miro_gen.transport.naming.client import (
    DEFAULT_HOLD,
    DEFAULT_LEASE,
    DEFAULT_MAX_NAMES,
    DEFAULT_QUOTA,
    MAX_PAGE,
    NAMING_KEY,
)
from miro_gen.transport.naming.owners_log import OwnersLog, Restored
from miro_gen.transport.naming.table import Holder, Table, check_entry, check_name
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.rpc import caller
from miro_gen.transport.rpc.adapter import ObjectAdapter
from miro_gen.transport.rpc.invoker import ZmqInvoker

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

PURGE_INTERVAL = 0.25  # seconds between sweeps for ended leases and holds
MAX_PAGE_BYTES = 1 << 20  # of a page of a listing (less when the message size is smaller)


class Registry(MiroNaming__POA.Registry):
    """The naming service's servant. Its operations are quick and run on the reactor thread,
    in the order requests arrive (ZeroMQ takes them from every connection in turn): a flood
    from one peer cannot hold back another server's renewal behind a queue of workers.
    `local_socket`: this machine's processes must bind through the Unix socket. `admit`: why
    a caller may not bind, unbind or renew a name (None for a renewal's), or None when it may."""

    def __init__(
        self,
        table: Table,
        log: OwnersLog | None = None,
        *,
        local_socket: str | None = None,
        page_bytes: int = MAX_PAGE_BYTES,
        admit: Callable[[caller.Caller, str | None], str | None] | None = None,
    ) -> None:
        self.table = table
        self.admit = admit
        self.log = log
        self.local_socket = local_socket
        self.page_bytes = page_bytes
        self.refused = 0  # binds refused: another owner's name, a quota, the table's size
        self._lock = threading.Lock()  # the operations' thread and the reactor's sweeps

    # ---- operations ---------------------------------------------------------------------------

    @nonblocking
    def bind_as(
        self, binding: MiroNaming.Entry, who: MiroNaming.Owner, lease_ms: int, take_over: bool
    ) -> None:
        holder = self._holder(who, check_name(binding.name))
        name = check_entry(binding, holder)
        with self._lock:
            try:
                b, how, given_up = self.table.bind(
                    binding, holder, lease_ms, take_over, time.monotonic(), time.time()
                )
            except MiroNaming.AlreadyBound as e:
                self._refuse("%s: held by %s", name, e.holder)
                raise
            except NO_RESOURCES as e:  # a quota, the table's size
                self._refuse("%s", e.message)
                raise
            for gone in given_up:
                _log.info("gave up %s, kept for a server that stopped, to make room", gone)
                self._freed(gone)
            if self.log is not None:
                self.log.bound(b)
        if how != "rebound":
            _log.info("%s %s (%s at %s)", how, name, binding.repo_id, binding.endpoint)

    @nonblocking
    def resolve(self, name: str) -> MiroNaming.Entry:
        check_name(name)
        with self._lock:
            b = self.table.live(name, time.monotonic())
        if b is None:
            raise MiroNaming.NotFound(name=name)
        return b.entry

    @nonblocking
    def unbind_as(self, name: str, who: MiroNaming.Owner) -> None:
        check_name(name)
        holder = self._holder(who, name)
        with self._lock:
            if not self.table.unbind(name, holder):
                raise MiroNaming.NotFound(name=name)  # not an entry of this owner
            self._freed(name)
        _log.info("unbound %s", name)

    @nonblocking
    def list_page(self, prefix: str, after: str, how_many: int) -> MiroNaming.Page:
        how_many = max(1, min(how_many, MAX_PAGE))
        with self._lock:
            entries, more = self.table.page(
                prefix, after, how_many, self.page_bytes, time.monotonic()
            )
        return MiroNaming.Page(entries, more)

    @nonblocking
    def renew_as(self, who: MiroNaming.Owner, names: list[str], lease_ms: int) -> list[str]:
        """Extend the leases of this run's `names`; the names among them it does not hold."""
        holder = self._holder(who)
        with self._lock:
            return self.table.renew(holder, names, lease_ms, time.monotonic(), time.time())

    # ---- the service's own --------------------------------------------------------------------

    def keep(self, binding: MiroNaming.Entry) -> None:
        """Bind an entry of the naming service's own (a channel it hosts), without a lease."""
        check_name(binding.name)
        with self._lock:
            self.table.keep(binding, time.time())
        _log.info("bound %s (%s at %s)", binding.name, binding.repo_id, binding.endpoint)

    def end_lease(self, name: str, endpoint: str) -> bool:
        """End the lease of `name` now, if it is live and bound at `endpoint`: its server is
        known to be gone (the Zenoh backbone's liveliness, transport.zenoh.registry). The name
        is then kept for its owner, as one whose lease ran out; whether it was live."""
        now = time.monotonic()
        with self._lock:
            b = self.table.get(name)
            if b is None or b.entry.endpoint != endpoint or not b.live(now):
                return False
            b.expires = now
        return True

    def purge(self) -> None:
        """Keep the bindings whose leases ended for their owners; forget those kept long
        enough."""
        now = time.time()
        with self._lock:
            lapsed, gone = self.table.lapse(time.monotonic(), now)
            for name in lapsed:
                b = self.table.get(name)
                if self.log is not None and b is not None:
                    self.log.lapsed(name, b.seen)
            for name in gone:
                self._freed(name)
        for name in lapsed:
            _log.info("the lease of %s ran out; the name is kept for its owner", name)
        for name in gone:
            _log.info("%s is free: its owner did not come back", name)

    # ---- internals ----------------------------------------------------------------------------

    def _holder(self, who: MiroNaming.Owner, name: str | None = None) -> Holder:
        """The owner of a call about `name` (None: a renewal): the caller's principal, and the
        service and run it says."""
        c = caller.current()
        if c is None:  # not through an adapter that identifies callers: a defect
            raise NO_PERMISSION("the naming service cannot tell who calls")
        if self.local_socket is not None and c.local and not c.verified:
            self._refuse("a call from this machine over TCP (%s)", who.service[:100])
            raise NO_PERMISSION(
                "processes on the naming service's machine bind through its local socket "
                f"({self.local_socket}), where it can tell who they are: an older miro-gen?"
            )
        if self.admit is not None:
            why = self.admit(c, name)
            if why is not None:
                self._refuse("%s for %s: %s", name or "a renewal", c.principal[:100], why)
                raise NO_PERMISSION(why)
        return Holder(c.principal, who.service, who.run)

    def _freed(self, name: str) -> None:
        if self.log is not None:
            self.log.freed(name)

    def _refuse(self, text: str, *args: object) -> None:
        self.refused += 1
        _peer_warnings.warning("refused to bind " + text, *args, key="refused to bind")


class NamingService:
    """A naming service hosted on `reactor` at `endpoint` (a fixed port) and at its Unix
    socket; `host` is the address it advertises for what it hosts when it listens on all
    interfaces; `log_path` keeps owners across restarts (None: nothing is kept, and say so)."""

    def __init__(
        self,
        reactor: Reactor,
        invoker: ZmqInvoker,
        endpoint: str,
        host: str | None = None,
        quota: int = DEFAULT_QUOTA,
        max_names: int = DEFAULT_MAX_NAMES,
        *,
        hold: float = DEFAULT_HOLD,
        log_path: str | None = None,
    ) -> None:
        self.table = Table(quota, max_names, hold)
        self.adapter = ObjectAdapter(
            reactor,
            invoker,
            bind=endpoint,
            host=host,
            also_bind=lambda bound: [s for s in [naming_socket(bound)] if s],
            identify_callers=True,
            serve=False,  # callers wait until the registry is there
        )
        self.endpoint = self.adapter.endpoint
        self.local_socket = next(iter(self.adapter.also_bound), None)
        self.log: OwnersLog | None = None
        self.restored = Restored()
        try:
            if log_path is not None:
                self.log = OwnersLog(log_path, self.table)
                self.restored = self.log.restore(time.monotonic(), DEFAULT_LEASE)
        except BaseException:
            self.adapter.close()
            raise
        size = sockets.policy(reactor.context).max_message_size
        self.registry = Registry(
            self.table,
            self.log,
            local_socket=self.local_socket,
            page_bytes=min(MAX_PAGE_BYTES, size // 2),
        )
        self.adapter.activate(self.registry, NAMING_KEY)
        self.adapter.serve()
        self._timer = reactor.schedule_timer(PURGE_INTERVAL, PURGE_INTERVAL, self._purge)

    def _purge(self, _: Any) -> None:
        self.registry.purge()

    def close(self) -> None:
        self.adapter.reactor.cancel_timer(self._timer)
        self.adapter.close()
        if self.log is not None:
            self.log.close()
