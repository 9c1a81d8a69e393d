"""The naming service: names (paths such as `robot1/ExampleA`) bound to object references.

It is itself a remote object, `MiroNaming::Registry` (idl/MiroNaming.idl), served under the key
`NameService` at a well-known endpoint (`tcp://127.0.0.1:2809` by default). Entries are held under
leases that their servers renew, so the names of a server that dies expire, and a restarted
naming service learns the names of the live servers at their next renewal.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import MiroNaming
import MiroNaming__POA

from miro_gen.exceptions import COMM_FAILURE, TIMEOUT, TRANSIENT
from miro_gen.log import logger
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.transport.adapter import ObjectAdapter
from miro_gen.transport.invoker import ZmqInvoker
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")

NAMING_KEY = b"NameService"
NAMING_OWNER = "miro-naming"  # the owner of the entries the naming service binds itself
DEFAULT_LEASE = 3.0  # seconds an entry lives without renewal
PURGE_INTERVAL = 0.25  # seconds between sweeps for expired entries
Entry = MiroNaming.Entry
NAMING_HINT = "is `miro naming` running? see --naming / MIRO_NAMING"


def check_name(name: str) -> str:
    """`name` as a canonical path (no empty parts); InvalidName otherwise."""
    parts = name.split("/")
    if not name or any(not p or p != p.strip() for p in parts):
        raise MiroNaming.InvalidName(name=name)
    return name


@dataclass
class _Binding:
    entry: MiroNaming.Entry
    owner: str
    expires: float


class Registry(MiroNaming__POA.Registry):
    """The naming service's servant: a table of leased entries."""

    def __init__(self) -> None:
        self._table: dict[str, _Binding] = {}
        self._lock = threading.Lock()

    def bind(self, binding: MiroNaming.Entry, owner: str, lease_ms: int) -> None:
        name = check_name(binding.name)
        with self._lock:
            old = self._live(name)
            if old is not None and old.owner != owner:
                raise MiroNaming.AlreadyBound(name=name)
            self._table[name] = _Binding(binding, owner, _expiry(lease_ms))
        _log.info("bound %s (%s at %s)", name, binding.repo_id, binding.endpoint)

    def rebind(self, binding: MiroNaming.Entry, owner: str, lease_ms: int) -> None:
        name = check_name(binding.name)
        with self._lock:
            self._table[name] = _Binding(binding, owner, _expiry(lease_ms))
        _log.info("bound %s (%s at %s)", name, binding.repo_id, binding.endpoint)

    def keep(self, binding: MiroNaming.Entry) -> None:
        """Bind an entry of the naming service's own (a channel it hosts), without a lease."""
        name = check_name(binding.name)
        with self._lock:
            self._table[name] = _Binding(binding, NAMING_OWNER, math.inf)
        _log.info("bound %s (%s at %s)", name, binding.repo_id, binding.endpoint)

    def resolve(self, name: str) -> MiroNaming.Entry:
        check_name(name)
        with self._lock:
            b = self._live(name)
        if b is None:
            raise MiroNaming.NotFound(name=name)
        return b.entry

    def unbind(self, name: str) -> None:
        check_name(name)
        with self._lock:
            if self._live(name) is None:
                raise MiroNaming.NotFound(name=name)
            del self._table[name]
        _log.info("unbound %s", name)

    def _list(self, prefix: str) -> list[MiroNaming.Entry]:  # IDL "list"
        with self._lock:
            self.purge()
            return [b.entry for n, b in sorted(self._table.items()) if n.startswith(prefix)]

    def renew(self, owner: str, lease_ms: int) -> bool:
        if owner == NAMING_OWNER:  # its own entries have no lease to renew
            return False
        expires = _expiry(lease_ms)
        found = False
        with self._lock:
            for b in self._table.values():
                if b.owner == owner and b.expires > time.monotonic():
                    b.expires = expires
                    found = True
        return found

    def purge(self) -> None:
        """Forget the entries whose leases ran out (callers hold the lock, or not: it is safe)."""
        now = time.monotonic()
        for name in [n for n, b in self._table.items() if b.expires <= now]:
            _log.info("the lease of %s ran out", name)
            del self._table[name]

    def _live(self, name: str) -> _Binding | None:
        b = self._table.get(name)
        if b is not None and b.expires <= time.monotonic():
            del self._table[name]
            return None
        return b


def _expiry(lease_ms: int) -> float:
    return time.monotonic() + max(lease_ms, 1) / 1000


class NamingService:
    """A naming service hosted on `reactor` at `endpoint` (a fixed port); `host` is the address
    it advertises for what it hosts when it listens on all interfaces."""

    def __init__(
        self, reactor: Reactor, invoker: ZmqInvoker, endpoint: str, host: str | None = None
    ) -> None:
        self.registry = Registry()
        self.adapter = ObjectAdapter(reactor, invoker, bind=endpoint, host=host)
        self.endpoint = self.adapter.endpoint
        self.adapter.activate(self.registry, NAMING_KEY)
        self._timer = reactor.schedule_timer(PURGE_INTERVAL, PURGE_INTERVAL, self._purge)

    def _purge(self, _: Any) -> None:
        with self.registry._lock:
            self.registry.purge()

    def close(self) -> None:
        self.adapter.reactor.cancel_timer(self._timer)
        self.adapter.close()


class NamingClient:
    """Binds and resolves names for a process whose naming context is `context`."""

    def __init__(self, invoker: ZmqInvoker, endpoint: str, context: str) -> None:
        self.context = context
        ref = ObjectRef(MiroNaming.Registry._repo_id, endpoint, NAMING_KEY)
        self.registry = MiroNaming.Registry(ref, invoker, timeout=5.0)

    def full_name(self, name: str) -> str:
        """A name as bound by this process: under its context unless it is a path already."""
        return name if "/" in name else f"{self.context}/{name}"

    def resolve(self, name: str) -> MiroNaming.Entry:
        """The entry of `name`: a path as it is; a plain name in this process's context first,
        then at the root. NotFound names what was looked for."""
        with naming_errors(self.registry._ref.endpoint, f"resolve {name}"):
            return self._resolve(name)

    def _resolve(self, name: str) -> MiroNaming.Entry:
        if "/" in name:
            return self.registry.resolve(name)
        try:
            return self.registry.resolve(f"{self.context}/{name}")
        except MiroNaming.NotFound:
            try:
                return self.registry.resolve(name)
            except MiroNaming.NotFound:
                raise MiroNaming.NotFound(name=f"{self.context}/{name}") from None


@contextlib.contextmanager
def naming_errors(endpoint: str, what: str) -> Iterator[None]:
    """Failures to reach the naming service, said as such, with what to do about them."""
    try:
        yield
    except (TRANSIENT, COMM_FAILURE, TIMEOUT) as e:
        reason = e.message.rsplit(": ", 1)[-1] if ": " in e.message else e.message
        raise TRANSIENT(
            f"cannot {what}: the naming service at {endpoint} cannot be reached ({reason}): "
            f"{NAMING_HINT}",
            e.minor,
            e.completed,
        ) from None
