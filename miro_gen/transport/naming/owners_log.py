"""The naming service's log of owners: what it binds, survives its restarts (as omniNames keeps
its log), so that a restarted naming service knows whose each name is before any server renews.

One JSON object per line, after a first line `{"miro-naming-log": 1}`:

    {"op": "bind", "name": ..., "repo_id": ..., "endpoint": ..., "key": HEX, "type_hash": ...,
     "principal": ..., "service": ..., "run": ..., "seen": WALL_SECONDS, "lease_ms": N}
    {"op": "lapse", "name": ..., "seen": WALL_SECONDS}   # its lease ended: kept for its owner
    {"op": "free", "name": ...}                           # unbound, or no longer kept

Binds, lapses and frees are appended as they happen (written to the kernel at once: a naming
service killed outright loses nothing); renewals are not: an entry that was live when the log
is read back gets a new lease, in which its server, if it runs, renews it.
When the log has grown to twice the table, and when it is opened, it is rewritten as the table
it describes (a new file renamed over the old one). The file is the user's (mode 0600 in a 0700
folder), locked (`PATH.lock`) while a naming service uses it; a line that does not parse (a
disk that filled up mid-line) is skipped with a warning, never a crash.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO, Any

import MiroNaming

from miro_gen.exceptions import BAD_PARAM
from miro_gen.log import logger
from miro_gen.transport.local import network_namespace
from miro_gen.transport.naming.table import MAX_LEASE_MS, Binding, Holder, Table, check_entry

_log = logger("MIRO")

HEADER = {"miro-naming-log": 1}
_CREATE = os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC
MIN_COMPACT_LINES = 1000  # a log shorter than this is never rewritten while running


class LogError(Exception):
    """The log cannot be used (another naming service holds it, it is not a log, no room)."""


def default_path(endpoint: str) -> str:
    """`$XDG_STATE_HOME/miro/naming-PORT.log` (`~/.local/state/...`) for a naming service at
    `endpoint`; `naming-PORT-NAME.log` in the network namespace `ip netns` named NAME, so that
    naming services of two namespaces on one port keep logs of their own."""
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(
        os.path.expanduser("~"), ".local", "state"
    )
    port = endpoint.rpartition(":")[2]
    name = _namespace_name()
    return os.path.join(base, "miro", f"naming-{port}{f'-{name}' if name else ''}.log")


def _namespace_name() -> str | None:
    """The name `ip netns` gave this process's network namespace (which lasts, where the
    inodes of deleted namespaces are given to new ones), or None (the machine's own, or one
    of a container)."""
    inode = network_namespace()
    for folder in ("/run/netns", "/var/run/netns"):
        with contextlib.suppress(OSError):
            for entry in os.scandir(folder):
                with contextlib.suppress(OSError):
                    if str(entry.stat().st_ino) == inode:
                        return entry.name
    return None


@dataclass
class Restored:
    """What reading a log gave back."""

    bindings: int = 0
    kept: int = 0
    skipped: int = 0  # lines that did not parse, or entries the table had no room for


class OwnersLog:
    """The log at `path`, opened (and locked) for a naming service whose table is `table`."""

    def __init__(self, path: str, table: Table) -> None:
        self.path = path
        self.table = table
        self._lines = 0
        folder = os.path.dirname(path) or "."
        try:
            os.makedirs(folder, mode=0o700, exist_ok=True)
            lock = os.open(f"{path}.lock", _CREATE | os.O_RDWR, 0o600)
        except OSError as e:
            raise LogError(f"cannot open the log of owners {path}: {e.strerror or e}") from None
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(lock)
            raise LogError(
                f"the log of owners {path} is in use by another naming service"
            ) from None
        self._lock = lock  # held while this naming service runs: the log is rewritten, not it
        try:
            fd = os.open(path, _CREATE | os.O_RDWR | os.O_APPEND, 0o600)
        except OSError as e:
            os.close(lock)
            raise LogError(f"cannot open the log of owners {path}: {e.strerror or e}") from None
        self._file: IO[str] = os.fdopen(fd, "a+", encoding="utf-8")

    # ---- reading back -------------------------------------------------------------------------

    def restore(self, mono: float, lease: float) -> Restored:
        """Fill the table from the log (`mono`: the monotonic time now), then rewrite the log
        as the table. An entry that was live gets a lease of `lease` seconds (or its own, if
        longer) from now, in which its server, if it still runs, renews it: while the naming
        service was down, nobody could. The others stay kept for their owners."""
        done = Restored()
        records: dict[str, tuple[dict[str, Any], float | None]] = {}  # name -> bind, lapsed at
        self._file.seek(0)
        first = True
        for number, line in enumerate(self._file, 1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except ValueError:
                record = None
            if first:
                first = False
                if record != HEADER:
                    raise LogError(f"{self.path}:1: not a log of owners of a naming service")
                continue
            if not _apply(record, records):
                done.skipped += 1
                _log.warning("%s:%d: skipped a line that does not parse", self.path, number)
        now = time.time()
        for name, (record, lapsed_at) in records.items():
            kept = lapsed_at is not None
            if kept:
                b = _binding(record, 0.0, lapsed_at or 0.0)
            else:
                b = _binding(record, mono + max(lease, _lease(record)), now)
            if b is None:
                done.skipped += 1
                _log.warning("%s: skipped the entry of %s, which is not valid", self.path, name)
            elif b.seen + self.table.hold <= now:
                continue  # kept long enough already
            elif not self.table.restore(b, kept):
                done.skipped += 1
            elif kept:
                done.kept += 1
            else:
                done.bindings += 1
        self.compact()
        return done

    # ---- writing ------------------------------------------------------------------------------

    def bound(self, b: Binding) -> None:
        self._append(_bind_record(b))

    def lapsed(self, name: str, seen: float) -> None:
        self._append({"op": "lapse", "name": name, "seen": seen})

    def freed(self, name: str) -> None:
        self._append({"op": "free", "name": name})

    def _append(self, record: dict[str, Any]) -> None:
        try:
            self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
            self._file.flush()
        except OSError as e:  # a full disk must not stop the naming service
            _log.warning("cannot write the log of owners %s: %s", self.path, e.strerror or e)
            return
        self._lines += 1
        if self._lines > max(MIN_COMPACT_LINES, 2 * len(self.table)):
            self.compact()

    def compact(self) -> None:
        """Rewrite the log as the table (a new file, synced, renamed over the old one)."""
        temporary = f"{self.path}.new"
        try:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(temporary)
            fd = os.open(temporary, _CREATE | os.O_EXCL | os.O_WRONLY, 0o600)
            with os.fdopen(fd, "w", encoding="utf-8") as out:
                for line in self._snapshot():
                    out.write(line)
                out.flush()
                os.fsync(out.fileno())
            os.replace(temporary, self.path)
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError as e:
            _log.warning("cannot rewrite the log of owners %s: %s", self.path, e.strerror or e)
            return
        self._file.close()
        self._file = os.fdopen(fd, "a", encoding="utf-8")
        self._lines = 0

    def _snapshot(self) -> Iterator[str]:
        yield json.dumps(HEADER) + "\n"
        for b in self.table.bindings():
            if b.holder.principal:  # not the naming service's own
                yield json.dumps(_bind_record(b), separators=(",", ":")) + "\n"
                if self.table.kept(b.entry.name):
                    yield json.dumps({"op": "lapse", "name": b.entry.name, "seen": b.seen}) + "\n"

    def close(self) -> None:
        self.compact()
        self._file.close()
        with contextlib.suppress(OSError):  # held: nobody else uses the log meanwhile
            os.unlink(f"{self.path}.lock")
        os.close(self._lock)


def _bind_record(b: Binding) -> dict[str, Any]:
    e = b.entry
    return {
        "op": "bind",
        "name": e.name,
        "repo_id": e.repo_id,
        "endpoint": e.endpoint,
        "key": bytes(e.key).hex(),
        "type_hash": e.type_hash,
        "principal": b.holder.principal,
        "service": b.holder.service,
        "run": b.holder.run,
        "seen": b.seen,
        "lease_ms": b.lease_ms,
    }


def _apply(record: Any, records: dict[str, tuple[dict[str, Any], float | None]]) -> bool:
    """Apply one line to what was read so far; whether it made sense."""
    if not isinstance(record, dict) or not isinstance(record.get("name"), str):
        return False
    name = record["name"]
    op = record.get("op")
    if op == "bind":
        records[name] = (record, None)
    elif op == "lapse" and isinstance(record.get("seen"), int | float):
        if name in records:
            records[name] = (records[name][0], float(record["seen"]))
    elif op == "free":
        records.pop(name, None)
    else:
        return False
    return True


def _lease(record: dict[str, Any]) -> float:
    """The lease, in seconds, a bind record was made with (0 when it does not say)."""
    lease = record.get("lease_ms")
    return lease / 1000 if isinstance(lease, int) and 0 < lease <= MAX_LEASE_MS else 0.0


def _binding(record: dict[str, Any], expires: float, seen: float) -> Binding | None:
    """The binding a bind record describes, checked as a bind is; None if it is not valid."""
    try:
        entry = MiroNaming.Entry(
            str(record["name"]),
            str(record["repo_id"]),
            str(record["endpoint"]),
            bytes.fromhex(str(record["key"])),
            str(record["type_hash"]),
        )
        holder = Holder(str(record["principal"]), str(record["service"]), str(record["run"]))
        if not holder.principal:
            return None
        check_entry(entry, holder)
        return Binding(entry, holder, expires, seen, int(_lease(record) * 1000))
    except (KeyError, ValueError, TypeError, MiroNaming.InvalidName, BAD_PARAM):
        return None
