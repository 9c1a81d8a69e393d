"""The naming service: names (paths such as `robot1/ExampleA`) bound to object references.

It is itself a remote object, `MiroNaming::Registry` (idl/MiroNaming.idl), served under the key
`NameService` at a well-known endpoint (`tcp://127.0.0.1:2809` by default). Entries are held under
leases that their servers renew, so the names of a server that dies expire, and a restarted
naming service learns the names of the live servers at their next renewal.

An entry belongs to its *owner* (a random id per server process, known only to it and to the
service): another owner can neither replace nor remove it while its lease runs, and renewals
say, name by name, which entries the owner has lost, so that it binds them again. Every owner
has a quota of names, the table a size limit, and every field of an entry a length limit:
what the service holds is bounded whatever its peers send (docs/SECURITY.md).
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

from miro_gen.exceptions import (
    BAD_PARAM,
    COMM_FAILURE,
    NO_RESOURCES,
    TIMEOUT,
    TRANSIENT,
    actionable,
)
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import nonblocking
from miro_gen.transport.adapter import ObjectAdapter
from miro_gen.transport.invoker import REFUSED_MINOR, ZmqInvoker
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

NAMING_KEY = b"NameService"
NAMING_OWNER = "miro-naming"  # the owner of the entries the naming service binds itself
DEFAULT_LEASE = 3.0  # seconds an entry lives without renewal
MAX_LEASE_MS = 60_000  # a longer lease asked for is cut to this
PURGE_INTERVAL = 0.25  # seconds between sweeps for expired entries
DEFAULT_QUOTA = 1000  # live names per owner
DEFAULT_MAX_NAMES = 20_000  # live names in all
MAX_NAME_BYTES = 1024  # of a name, UTF-8
MAX_FIELD_BYTES = 1024  # of an entry's repository id, endpoint, key and type hash each
MAX_OWNER_BYTES = 128
Entry = MiroNaming.Entry
NAMING_HINT = "is `miro naming` running? see --naming / MIRO_NAMING"

# The naming errors a program lets through are the user's to fix: one line each (lifecycle).
actionable(
    MiroNaming.NotFound,
    lambda e: (
        f"{e.name} is not bound in the naming service: is its server running? "
        "(`miro nslist` lists what is)"
    ),
)
actionable(MiroNaming.InvalidName, lambda e: f"InvalidName: {e.name}")
actionable(MiroNaming.AlreadyBound, lambda e: f"AlreadyBound: {e.name}")


def check_name(name: str) -> str:
    """`name` as a canonical path (no empty parts, at most MAX_NAME_BYTES); InvalidName
    otherwise."""
    parts = name.split("/")
    if (
        not name
        or len(name.encode("utf-8", "replace")) > MAX_NAME_BYTES
        or any(not p or p != p.strip() for p in parts)
    ):
        raise MiroNaming.InvalidName(name=name[:MAX_NAME_BYTES])
    return name


def _check_entry(entry: MiroNaming.Entry, owner: str) -> str:
    """The entry's name, after checking the entry's and the owner's sizes."""
    name = check_name(entry.name)
    for field in ("repo_id", "endpoint", "type_hash"):
        if len(getattr(entry, field).encode("utf-8", "replace")) > MAX_FIELD_BYTES:
            raise BAD_PARAM(f"{name}: the entry's {field} is longer than {MAX_FIELD_BYTES} bytes")
    if len(entry.key) > MAX_FIELD_BYTES:
        raise BAD_PARAM(f"{name}: the entry's key is longer than {MAX_FIELD_BYTES} bytes")
    _check_owner(owner)
    return name


def _check_owner(owner: str) -> None:
    if not owner or len(owner.encode("utf-8", "replace")) > MAX_OWNER_BYTES:
        raise BAD_PARAM(f"an owner id is 1 to {MAX_OWNER_BYTES} bytes")


@dataclass
class _Binding:
    entry: MiroNaming.Entry
    owner: str
    expires: float


class Registry(MiroNaming__POA.Registry):
    """The naming service's servant: a table of leased entries, each of one owner. Its
    operations are quick and run on the reactor thread, in the order requests arrive (ZeroMQ
    takes them from every connection in turn): a flood from one peer cannot hold back another
    server's renewal behind a queue of workers."""

    def __init__(self, quota: int = DEFAULT_QUOTA, max_names: int = DEFAULT_MAX_NAMES) -> None:
        self.quota = quota
        self.max_names = max_names
        self._table: dict[str, _Binding] = {}
        self._counts: dict[str, int] = {}  # owner -> live entries
        self._lock = threading.Lock()
        self.refused = 0  # binds refused: another owner's name, a quota, the table's size

    @nonblocking
    def bind(self, binding: MiroNaming.Entry, owner: str, lease_ms: int) -> None:
        self._bind(binding, owner, lease_ms)

    @nonblocking
    def rebind(self, binding: MiroNaming.Entry, owner: str, lease_ms: int) -> None:
        # The same as bind: replacing another owner's live entry is what a stranger, or a
        # second copy of a server, must not do; the owner's own entry is replaced.
        self._bind(binding, owner, lease_ms)

    def _bind(self, binding: MiroNaming.Entry, owner: str, lease_ms: int) -> None:
        name = _check_entry(binding, owner)
        if owner == NAMING_OWNER:  # nobody binds in the name of the service itself
            self._refuse("%s: bound with the naming service's own owner id", name)
            raise MiroNaming.AlreadyBound(name=name)
        with self._lock:
            old = self._live(name)
            if old is not None and old.owner != owner:
                self._refuse("%s: held by another owner", name)
                raise MiroNaming.AlreadyBound(name=name)
            if old is None:
                if self._counts.get(owner, 0) >= self.quota:
                    self._refuse("%s: its owner has %d names, its quota", name, self.quota)
                    raise NO_RESOURCES(f"{name}: this server already has {self.quota} names")
                if len(self._table) >= self.max_names:
                    self._purge()
                    if len(self._table) >= self.max_names:
                        self._refuse("%s: the table holds %d names", name, self.max_names)
                        raise NO_RESOURCES(f"{name}: the naming service is full")
                self._counts[owner] = self._counts.get(owner, 0) + 1
            self._table[name] = _Binding(binding, owner, _expiry(lease_ms))
        _log.info("bound %s (%s at %s)", name, binding.repo_id, binding.endpoint)

    def _refuse(self, text: str, *args: object) -> None:
        self.refused += 1
        _peer_warnings.warning("refused to bind " + text, *args, key="refused to bind")

    def keep(self, binding: MiroNaming.Entry) -> None:
        """Bind an entry of the naming service's own (a channel it hosts), without a lease."""
        name = check_name(binding.name)
        with self._lock:
            self._remove(name)
            self._table[name] = _Binding(binding, NAMING_OWNER, math.inf)
            self._counts[NAMING_OWNER] = self._counts.get(NAMING_OWNER, 0) + 1
        _log.info("bound %s (%s at %s)", name, binding.repo_id, binding.endpoint)

    @nonblocking
    def resolve(self, name: str) -> MiroNaming.Entry:
        check_name(name)
        with self._lock:
            b = self._live(name)
        if b is None:
            raise MiroNaming.NotFound(name=name)
        return b.entry

    @nonblocking
    def unbind(self, name: str, owner: str) -> None:
        check_name(name)
        with self._lock:
            b = self._live(name)
            if b is None or b.owner != owner or owner == NAMING_OWNER:
                raise MiroNaming.NotFound(name=name)  # not a live entry of this owner
            self._remove(name)
        _log.info("unbound %s", name)

    @nonblocking
    def _list(self, prefix: str) -> list[MiroNaming.Entry]:  # IDL "list"
        with self._lock:
            self._purge()
            return [b.entry for n, b in sorted(self._table.items()) if n.startswith(prefix)]

    @nonblocking
    def renew(self, owner: str, names: list[str], lease_ms: int) -> list[str]:
        """Extend the leases of `owner`'s `names`; the names among them it does not hold."""
        if owner == NAMING_OWNER:  # its own entries have no lease to renew
            return list(names)
        expires = _expiry(lease_ms)
        lost = []
        with self._lock:
            for name in names:
                b = self._live(name)
                if b is not None and b.owner == owner:
                    b.expires = expires
                else:
                    lost.append(name)
        return lost

    def purge(self) -> None:
        """Forget the entries whose leases ran out."""
        with self._lock:
            self._purge()

    def _purge(self) -> None:  # callers hold the lock
        now = time.monotonic()
        for name in [n for n, b in self._table.items() if b.expires <= now]:
            _log.info("the lease of %s ran out", name)
            self._remove(name)

    def _live(self, name: str) -> _Binding | None:
        b = self._table.get(name)
        if b is not None and b.expires <= time.monotonic():
            self._remove(name)
            return None
        return b

    def _remove(self, name: str) -> None:
        b = self._table.pop(name, None)
        if b is not None:
            n = self._counts[b.owner] - 1
            if n:
                self._counts[b.owner] = n
            else:
                del self._counts[b.owner]


def _expiry(lease_ms: int) -> float:
    return time.monotonic() + min(max(lease_ms, 1), MAX_LEASE_MS) / 1000


class NamingService:
    """A naming service hosted on `reactor` at `endpoint` (a fixed port); `host` is the address
    it advertises for what it hosts when it listens on all interfaces."""

    def __init__(
        self,
        reactor: Reactor,
        invoker: ZmqInvoker,
        endpoint: str,
        host: str | None = None,
        quota: int = DEFAULT_QUOTA,
        max_names: int = DEFAULT_MAX_NAMES,
    ) -> None:
        self.registry = Registry(quota, max_names)
        self.adapter = ObjectAdapter(reactor, invoker, bind=endpoint, host=host)
        self.endpoint = self.adapter.endpoint
        self.adapter.activate(self.registry, NAMING_KEY)
        self._timer = reactor.schedule_timer(PURGE_INTERVAL, PURGE_INTERVAL, self._purge)

    def _purge(self, _: Any) -> None:
        self.registry.purge()

    def close(self) -> None:
        self.adapter.reactor.cancel_timer(self._timer)
        self.adapter.close()


class NamingClient:
    """Binds and resolves names for a process whose naming context is `context`."""

    def __init__(self, invoker: ZmqInvoker, endpoint: str, context: str) -> None:
        self.context = context
        self.endpoint = endpoint
        self.ref = ObjectRef(MiroNaming.Registry._repo_id, endpoint, NAMING_KEY)
        self.registry = self.registry_stub(invoker, 5.0)

    def registry_stub(self, invoker: ZmqInvoker, timeout: float) -> MiroNaming.Registry:
        """A stub of the naming service with its own call timeout (a lease renewer's)."""
        return MiroNaming.Registry(self.ref, invoker, timeout=timeout)

    def full_name(self, name: str) -> str:
        """A name as bound by this process: under its context unless it is a path already."""
        return name if "/" in name else f"{self.context}/{name}"

    def resolve(self, name: str) -> MiroNaming.Entry:
        """The entry of `name`: a path as it is; a plain name in this process's context first,
        then at the root. NotFound names what was looked for."""
        with naming_errors(self.endpoint, f"resolve {name}"):
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
        if e.minor == REFUSED_MINOR:  # it runs, but will not have us: say why
            raise TRANSIENT(f"cannot {what}: {e.message}", e.minor, e.completed) from None
        reason = e.message.rsplit(": ", 1)[-1] if ": " in e.message else e.message
        raise TRANSIENT(
            f"cannot {what}: the naming service at {endpoint} cannot be reached ({reason}): "
            f"{NAMING_HINT}",
            e.minor,
            e.completed,
        ) from None
