"""The naming service's table: which name is bound to what, who owns it, how long it lives, and
the limits that keep it bounded. No I/O and no clock of its own (callers pass the time): the
servant (`transport.naming.service`) asks it and writes what changed to its log
(`transport.naming.owners_log`).

An owner (`Holder`) is a *principal*, checked by the naming service (`transport.rpc.caller`), and a
*service* and a *run*, which the caller states. The rules, for a name held by a binding:

| the name is held      | same principal, service | same principal, other | other principal |
|-----------------------|-------------------------|-----------------------|-----------------|
| live, by this run     | rebound                 | -                     | -               |
| live, by another run  | taken over if take_over | AlreadyBound          | AlreadyBound    |
| kept (lease ended)    | taken back              | AlreadyBound          | AlreadyBound    |

A binding whose lease ends is *kept* for its owner for `hold` seconds after it was last renewed:
resolve no longer finds it, but nobody else may bind the name meanwhile, so a stranger that
polls cannot take the name of a server between its crash and its restart. Any process of the
same principal may release a kept binding (`unbind`, `miro nsunbind`): a service renamed, or
moved to another program. Kept bindings count in their principal's quota; a principal at its
quota, or a full table, gives up its oldest kept binding (the table's oldest, when full)
before refusing a new name.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable
from dataclasses import dataclass

import MiroNaming

from miro_gen.exceptions import BAD_PARAM, NO_RESOURCES

MAX_NAME_BYTES = 1024  # of a name, UTF-8
MAX_FIELD_BYTES = 1024  # of an entry's repository id, endpoint, key and type hash each
MAX_ENTRY_BYTES = 2048  # of all of them together, the name included
MAX_OWNER_BYTES = 256  # of a holder's service and run each
ENTRY_OVERHEAD = 32  # bytes of CDR around an entry's fields in a listing (lengths, alignment)
MAX_LEASE_MS = 60_000  # a longer lease asked for is cut to this
SERVICE_PRINCIPAL = ""  # the principal of the naming service's own entries: no caller's


@dataclass(frozen=True)
class Holder:
    """Who owns a binding: the checked principal, the service and the run it says it is."""

    principal: str
    service: str
    run: str


@dataclass
class Binding:
    """A name's entry and owner; `expires` (monotonic seconds) ends its lease, `seen` (wall
    seconds) is when its owner was last known alive, from which it is kept for `hold`."""

    entry: MiroNaming.Entry
    holder: Holder
    expires: float
    seen: float
    lease_ms: int = 0  # the lease it was bound or last renewed with

    def live(self, now: float) -> bool:
        return self.expires > now


def _lease_ms(lease_ms: int) -> int:
    return min(max(lease_ms, 1), MAX_LEASE_MS)


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


def entry_size(entry: MiroNaming.Entry) -> int:
    """The bytes of an entry's fields (what a listing of it costs, less ENTRY_OVERHEAD)."""
    return (
        sum(len(s.encode("utf-8", "replace")) for s in (entry.name, entry.repo_id, entry.endpoint))
        + len(entry.key)
        + len(entry.type_hash.encode("utf-8", "replace"))
    )


def check_entry(entry: MiroNaming.Entry, holder: Holder) -> str:
    """The entry's name, after checking the entry's and the holder's sizes (BAD_PARAM)."""
    name = check_name(entry.name)
    for field in ("repo_id", "endpoint", "type_hash"):
        if len(getattr(entry, field).encode("utf-8", "replace")) > MAX_FIELD_BYTES:
            raise BAD_PARAM(f"{name}: the entry's {field} is longer than {MAX_FIELD_BYTES} bytes")
    if len(entry.key) > MAX_FIELD_BYTES:
        raise BAD_PARAM(f"{name}: the entry's key is longer than {MAX_FIELD_BYTES} bytes")
    if entry_size(entry) > MAX_ENTRY_BYTES:
        raise BAD_PARAM(f"{name}: the entry is larger than {MAX_ENTRY_BYTES} bytes")
    check_holder(holder)
    return name


def check_holder(holder: Holder) -> None:
    for part in (holder.service, holder.run):
        if not part or len(part.encode("utf-8", "replace")) > MAX_OWNER_BYTES:
            raise BAD_PARAM(f"an owner's service and run are 1 to {MAX_OWNER_BYTES} bytes")


class Table:
    """Bindings by name, kept in name order, with quotas per principal (`quota` names, live
    or kept), at most `max_names` in all, and kept bindings held for `hold` seconds."""

    def __init__(self, quota: int, max_names: int, hold: float) -> None:
        self.quota = quota
        self.max_names = max_names
        self.hold = hold
        self._bindings: dict[str, Binding] = {}
        self._names: list[str] = []  # sorted
        self._counts: dict[str, int] = {}  # principal -> bindings, live or kept
        self._kept: dict[str, None] = {}  # names whose lease ended, oldest first
        self._kept_by: dict[str, dict[str, None]] = {}  # principal -> its kept names

    def __len__(self) -> int:
        return len(self._bindings)

    def get(self, name: str) -> Binding | None:
        return self._bindings.get(name)

    def bindings(self) -> list[Binding]:
        return list(self._bindings.values())

    def count(self, principal: str) -> int:
        return self._counts.get(principal, 0)

    # ---- changes ------------------------------------------------------------------------------

    def bind(
        self,
        entry: MiroNaming.Entry,
        holder: Holder,
        lease_ms: int,
        take_over: bool,
        mono: float,
        now: float,
    ) -> tuple[Binding, str, list[str]]:
        """Bind `entry` for `holder` for a lease of `lease_ms` (cut to MAX_LEASE_MS), at `mono`
        (monotonic) and `now` (wall): the binding, what happened ("bound", "rebound", "taken
        over", "taken back") and the names of kept bindings given up to make room.
        AlreadyBound, NO_RESOURCES."""
        name = entry.name
        lease_ms = _lease_ms(lease_ms)
        expires = mono + lease_ms / 1000
        b = self._bindings.get(name)
        if b is not None:
            if b.expires <= mono:
                self._keep(b)  # (its lease ended since the last sweep)
            self._refuse_if_held(b, holder, take_over)
            if name in self._kept:
                how = "taken back"
                self._unkeep(name, b.holder.principal)
            else:
                how = "rebound" if b.holder.run == holder.run else "taken over"
            b.entry, b.holder, b.expires, b.seen = entry, holder, expires, now
            b.lease_ms = lease_ms
            return b, how, []
        given_up = self._make_room(name, holder.principal)
        b = Binding(entry, holder, expires, now, lease_ms)
        self._add(b)
        return b, "bound", given_up

    def _refuse_if_held(self, b: Binding, holder: Holder, take_over: bool) -> None:
        name = b.entry.name
        kept = name in self._kept
        if b.holder.principal != holder.principal:
            if b.holder.principal == SERVICE_PRINCIPAL:
                raise MiroNaming.AlreadyBound(name, "the naming service itself")
            why = "its server stopped; the name is kept for it" if kept else "live"
            raise MiroNaming.AlreadyBound(name, f"another user or host ({why})")
        if b.holder.service != holder.service:
            if kept:
                raise MiroNaming.AlreadyBound(
                    name,
                    f"{b.holder.service}, another service of yours, kept since its server "
                    f"stopped (`miro nsunbind {name}` frees it)",
                )
            raise MiroNaming.AlreadyBound(name, f"{b.holder.service}, another service of yours")
        if kept:
            return  # its service's, whose server stopped: taken back
        if b.holder.run != holder.run and not take_over:
            raise MiroNaming.AlreadyBound(name, f"another run of {holder.service}")

    def keep(self, entry: MiroNaming.Entry, now: float) -> None:
        """Bind an entry of the naming service's own (a channel it hosts), without a lease."""
        self.remove(entry.name)
        self._add(Binding(entry, Holder(SERVICE_PRINCIPAL, "miro-naming", ""), math.inf, now))

    def unbind(self, name: str, holder: Holder) -> bool:
        """Remove `name` if this run of `holder` holds it, or it is kept for the same
        principal; whether it was."""
        b = self._bindings.get(name)
        if b is None or b.holder.principal == SERVICE_PRINCIPAL:
            return False
        kept = name in self._kept
        if b.holder != holder and not (kept and b.holder.principal == holder.principal):
            return False
        self.remove(name)
        return True

    def renew(
        self, holder: Holder, names: Iterable[str], lease_ms: int, mono: float, now: float
    ) -> list[str]:
        """Extend the leases of this run of `holder`'s live `names` by `lease_ms`; the others
        (lost)."""
        lease_ms = _lease_ms(lease_ms)
        expires = mono + lease_ms / 1000
        lost = []
        for name in names:
            b = self._bindings.get(name)
            if b is not None and b.holder == holder and b.expires > mono:
                b.expires, b.seen, b.lease_ms = expires, now, lease_ms
            else:
                lost.append(name)
        return lost

    def lapse(self, mono: float, now: float) -> tuple[list[str], list[str]]:
        """Bindings whose leases ended become kept; kept ones whose hold ended go. The names
        of both, in that order."""
        lapsed = [n for n, b in self._bindings.items() if b.expires <= mono and n not in self._kept]
        for name in lapsed:
            self._keep(self._bindings[name])
        gone = []
        for name in self._kept:  # oldest first: stop at the first still held
            if self._bindings[name].seen + self.hold > now:
                break
            gone.append(name)
        for name in gone:
            self.remove(name)
        return lapsed, gone

    def restore(self, b: Binding, kept: bool) -> bool:
        """Put back a binding read from the log (kept: its lease had ended); False if the
        table has no room for it (the log is longer than this table's limits)."""
        if b.entry.name in self._bindings:
            self.remove(b.entry.name)
        if len(self) >= self.max_names or self.count(b.holder.principal) >= self.quota:
            return False
        self._add(b)
        if kept:
            self._keep(b)
        return True

    def remove(self, name: str) -> None:
        b = self._bindings.pop(name, None)
        if b is None:
            return
        i = bisect.bisect_left(self._names, name)
        if i < len(self._names) and self._names[i] == name:
            del self._names[i]
        principal = b.holder.principal
        n = self._counts[principal] - 1
        if n:
            self._counts[principal] = n
        else:
            del self._counts[principal]
        self._unkeep(name, principal)

    # ---- questions ----------------------------------------------------------------------------

    def live(self, name: str, mono: float) -> Binding | None:
        b = self._bindings.get(name)
        return b if b is not None and b.expires > mono else None

    def kept(self, name: str) -> bool:
        return name in self._kept

    def page(
        self, prefix: str, after: str, how_many: int, max_bytes: int, mono: float
    ) -> tuple[list[MiroNaming.Entry], bool]:
        """Live entries whose names start with `prefix` and sort after `after`: at most
        `how_many` (at least one) and `max_bytes` of fields; whether more follow."""
        names = self._names
        i = bisect.bisect_right(names, after) if after else 0
        i = max(i, bisect.bisect_left(names, prefix))
        out: list[MiroNaming.Entry] = []
        size = 0
        while i < len(names) and names[i].startswith(prefix):
            b = self._bindings[names[i]]
            i += 1
            if b.expires <= mono:
                continue
            cost = entry_size(b.entry) + ENTRY_OVERHEAD
            if out and (len(out) >= how_many or size + cost > max_bytes):
                return out, True
            out.append(b.entry)
            size += cost
        return out, False

    # ---- internals ----------------------------------------------------------------------------

    def _add(self, b: Binding) -> None:
        name = b.entry.name
        self._bindings[name] = b
        bisect.insort(self._names, name)
        principal = b.holder.principal
        self._counts[principal] = self._counts.get(principal, 0) + 1

    def _keep(self, b: Binding) -> None:
        name = b.entry.name
        if name not in self._kept:
            self._kept[name] = None
            self._kept_by.setdefault(b.holder.principal, {})[name] = None

    def _unkeep(self, name: str, principal: str) -> None:
        if name in self._kept:
            del self._kept[name]
            mine = self._kept_by[principal]
            del mine[name]
            if not mine:
                del self._kept_by[principal]

    def _make_room(self, name: str, principal: str) -> list[str]:
        """Room for one more binding of `principal`: its oldest kept binding given up when it
        is at its quota, the table's oldest when the table is full. NO_RESOURCES when none."""
        given_up = []
        if self.count(principal) >= self.quota:
            mine = self._kept_by.get(principal)
            if not mine:
                raise NO_RESOURCES(f"{name}: this user or host already has {self.quota} names")
            oldest = next(iter(mine))
            self.remove(oldest)
            given_up.append(oldest)
        if len(self) >= self.max_names:
            if not self._kept:
                raise NO_RESOURCES(f"{name}: the naming service is full")
            oldest = next(iter(self._kept))
            self.remove(oldest)
            given_up.append(oldest)
        return given_up
