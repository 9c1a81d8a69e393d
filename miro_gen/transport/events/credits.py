"""Credits of keep-all consumers on one host, for events of every size (docs/PROTOCOL.md,
"Keep-all consumers"): how far a consumer has read each supplier's events, in a table of its
own in shared memory that its suppliers read, so that a supplier never has more frames in
flight toward it than the channel's queue for it holds.

The channel's proxy holds a bounded queue of frames per consumer (`channels.PROXY_HWM`, fewer
for large messages) and drops toward a consumer whose process is not scheduled for a while.
A keep-all consumer of the same host as its suppliers therefore keeps a `CreditTable`: per
(supplier, type) the next sequence number it is due, written as each frame is taken off its
socket (into its own queue, which is bounded in bytes). It announces the table with one more
subscription per prefix, `credit_marker()` + (pid, fd, table id) + the prefix, which no frame
matches and which reaches every supplier (the channel's XPUB is verbose). A supplier maps the
table (`CreditReader`, through `/proc/PID/fd/FD`, as the shared-memory ring is mapped) and
sends a frame of a topic that consumer takes only while fewer than `window` frames of that topic
are past the consumer's credit; otherwise the events wait in the supplier's queue, for at most
`shm.WAIT_KEEP_ALL` seconds, after which the supplier stops waiting for that consumer until it
returns a credit again (a dead or stopped consumer costs one bound, not one per event).

The table is a memfd, written by its consumer only, read by suppliers only: no locks. It goes
away with the last process that has it open. This module owns its bytes; no sockets, no reactor.
"""

from __future__ import annotations

import hashlib
import mmap
import os
import random
import struct
import time
from bisect import bisect_left
from collections.abc import Callable, Iterable
from typing import Final

from miro_gen.transport import shm

MAGIC: Final = b"MIROCRD1"
ENTRIES: Final = 4096  # (supplier, type) pairs a consumer's table holds; later ones get none
# Events of a topic in flight toward a consumer, at most (besides `window` frames): what the
# consumer must parse before its credit comes back (a few tenths of a second on a loaded
# machine), so that a live one that is merely busy returns it well within the bound. A frame
# always may go while none is in flight.
WINDOW_EVENTS: Final = 65_536
# The table: a header, then the entries. `used` is written after the entry it counts.
_HEAD = struct.Struct("<8sQII")  # magic, table id, entries, used
_ENTRY = struct.Struct("<QQQQ")  # supplier id, type key, next sequence number due, spare
_ENTRY_AT = 32
_USED_AT = 20
_DUE_AT = 16
_U32 = struct.Struct("<I")
_Q = struct.Struct("<Q")
_LAST = (1 << 64) - 1
# What a credit subscription carries after its marker: consumer pid, its fd of the table, the
# table id; then the prefix it credits.
ANNOUNCE: Final = struct.Struct("<IIQ")


def credit_marker() -> bytes:
    """What precedes a keep-all consumer's credit subscriptions (no frame starts with it); empty
    where the host key cannot be told (no shared memory there)."""
    key = shm.host_key()
    return b"\x03shm-" + key + b"\0" if key else b""


def type_key(type_name: str) -> int:
    """The 64-bit key of a type name in a table (a supplier's topics differ by type name)."""
    return int.from_bytes(hashlib.blake2b(type_name.encode(), digest_size=8).digest(), "little")


class CreditTable:
    """A keep-all consumer's table of credits (its one writer)."""

    def __init__(self, entries: int = ENTRIES) -> None:
        self.entries = entries
        self.table_id = random.getrandbits(63)
        size = _ENTRY_AT + entries * _ENTRY.size
        self.fd = os.memfd_create("miro-credits", os.MFD_CLOEXEC)
        try:
            os.ftruncate(self.fd, size)
            self._map = mmap.mmap(self.fd, size)
        except OSError:
            os.close(self.fd)
            raise
        self._mem = memoryview(self._map)
        _HEAD.pack_into(self._mem, 0, MAGIC, self.table_id, entries, 0)
        self._at: dict[tuple[int, str], int] = {}  # (supplier, type name) -> its entry's offset
        self._keys: dict[str, int] = {}
        self.closed = False

    def subscription(self, marker: bytes, prefix: bytes) -> bytes:
        """The subscription that announces this table to the suppliers of `prefix`."""
        return marker + ANNOUNCE.pack(os.getpid(), self.fd, self.table_id) + prefix

    def credit(self, supplier: int, type_name: str, due: int) -> None:
        """The next event due from `supplier`'s `type_name` is number `due`: every frame before
        it has left the channel's queue."""
        due = min(due, _LAST)  # (numbers come from the network: one past 2^64 - 1 is possible)
        at = self._at.get((supplier, type_name))
        if at is None:
            used = len(self._at)
            if used >= self.entries or self.closed:
                return  # full: that supplier gets no credits from here (it stops waiting)
            key = self._keys.get(type_name)
            if key is None:
                key = self._keys[type_name] = type_key(type_name)
            at = _ENTRY_AT + used * _ENTRY.size
            _ENTRY.pack_into(self._mem, at, supplier, key, due, 0)
            _U32.pack_into(self._mem, _USED_AT, used + 1)  # after the entry: readers see it whole
            self._at[(supplier, type_name)] = at
            return
        _Q.pack_into(self._mem, at + _DUE_AT, due)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        shm.unmap(self.fd, self._map, self._mem)


class CreditReader:
    """A supplier's mapping of a consumer's table, found from its credit subscription."""

    def __init__(self, pid: int, fd: int, table_id: int) -> None:
        self.pid, self.consumer_fd, self.table_id = pid, fd, table_id
        self.fd = os.open(f"/proc/{pid}/fd/{fd}", os.O_RDONLY | os.O_CLOEXEC)
        try:
            size = os.fstat(self.fd).st_size
            self._map = mmap.mmap(self.fd, size, prot=mmap.PROT_READ)
        except (OSError, ValueError):
            os.close(self.fd)
            raise
        self._mem = memoryview(self._map)
        try:
            magic, tid, entries, _ = _HEAD.unpack_from(self._mem, 0)
            if magic != MAGIC or tid != table_id or _ENTRY_AT + entries * _ENTRY.size > size:
                raise OSError("not the credit table the subscription names")
        except Exception:
            self.close()
            raise
        self.entries = entries
        self._seen = 0  # entries looked through so far
        self._found: dict[tuple[int, int], int] = {}  # (supplier, type key) -> entry offset
        # (supplier, type key) -> the credit it stopped being waited at: per flow, since the
        # flows of one type from two suppliers (a replay's robots) have credits of their own
        self.stalled: dict[tuple[int, int], int] = {}
        self.closed = False

    def due(self, supplier: int, key: int) -> int | None:
        """The next sequence number the consumer is due from `supplier`'s type `key`; None when
        it has had none of them yet."""
        if self.closed:
            return None
        try:  # (closed meanwhile by the reactor thread, when a replay's thread asks: None)
            at = self._found.get((supplier, key))
            if at is None:
                used = min(_U32.unpack_from(self._mem, _USED_AT)[0], self.entries)
                mem = self._mem
                for i in range(self._seen, used):
                    base = _ENTRY_AT + i * _ENTRY.size
                    s, k = struct.unpack_from("<QQ", mem, base)
                    self._found[(s, k)] = base
                self._seen = max(self._seen, used)
                at = self._found.get((supplier, key))
                if at is None:
                    return None
            return int(_Q.unpack_from(self._mem, at + _DUE_AT)[0])
        except ValueError:
            return None

    def alive(self) -> bool:
        """Whether the consumer still has its table open (its process is alive). False once
        closed: the reactor thread closes a table whose consumer unsubscribed while a replay's
        thread may still hold it in a list from before."""
        return not self.closed and shm.holds_open(self.pid, self.consumer_fd, self.fd)

    def close(self) -> None:
        self.closed = True
        shm.unmap(self.fd, self._map, self._mem)


def parse_subscription(marker: bytes, whole: bytes) -> tuple[tuple[int, int, int], bytes] | None:
    """((pid, fd, table id), prefix) of a credit subscription; None if `whole` is not one."""
    if not marker or not whole.startswith(marker) or len(whole) < len(marker) + ANNOUNCE.size:
        return None
    ident = ANNOUNCE.unpack_from(whole, len(marker))
    return (int(ident[0]), int(ident[1]), int(ident[2])), whole[len(marker) + ANNOUNCE.size :]


class KeepAllConsumers:
    """A supplier's keep-all consumers of its host, from their credit subscriptions (reactor
    thread): the tables it has mapped (at most MAX) and the prefixes each credits."""

    MAX = 64

    def __init__(self, marker: bytes) -> None:
        self.marker = marker
        self._subs: dict[bytes, int] = {}  # credit subscription -> how many times subscribed
        self._readers: dict[int, CreditReader] = {}  # by table id
        self._prefixes: list[tuple[bytes, CreditReader]] = []
        self.refused = 0  # credit subscriptions whose table could not be mapped

    def change(self, subscribed: bool, whole: bytes) -> bool:
        """Take a (un)subscription; False when it is not a credit subscription."""
        found = parse_subscription(self.marker, whole)
        if found is None:
            return False
        n = self._subs.get(whole, 0) + (1 if subscribed else -1)
        if n > 0:
            self._subs[whole] = n
        else:
            self._subs.pop(whole, None)
        self._update()
        return True

    def _update(self) -> None:
        wanted: dict[int, tuple[int, int, int]] = {}
        prefixes: list[tuple[bytes, int]] = []
        for whole in self._subs:
            found = parse_subscription(self.marker, whole)
            if found is not None:
                wanted.setdefault(found[0][2], found[0])
                prefixes.append((found[1], found[0][2]))
        for table_id in list(self._readers):
            if table_id not in wanted:
                self._readers.pop(table_id).close()
        for table_id, (pid, fd, _) in wanted.items():
            if table_id in self._readers or len(self._readers) >= self.MAX:
                continue
            try:
                self._readers[table_id] = CreditReader(pid, fd, table_id)
            except (OSError, ValueError, struct.error):
                self.refused += 1
        self._prefixes = [(p, self._readers[i]) for p, i in prefixes if i in self._readers]

    def _matching(self, frame: bytes) -> dict[int, tuple[CreditReader, int]]:
        """The tables of the consumers that take the topic `frame`, by table id, each with how
        many of its subscriptions match."""
        found: dict[int, tuple[CreditReader, int]] = {}
        for prefix, reader in self._prefixes:
            if frame.startswith(prefix):
                found[reader.table_id] = (reader, found.get(reader.table_id, (reader, 0))[1] + 1)
        return found

    def matching(self, frame: bytes) -> list[CreditReader]:
        """The tables of the consumers that take the topic `frame` (each once)."""
        return [reader for reader, _ in self._matching(frame).values()]

    def lanes(self, frame: bytes, subscriptions: int) -> int:
        """How many keep-all consumers' lanes a ring of the topic `frame` waits for
        (transport.shm), given the `subscriptions` after shm.keep_all_marker that match it: one
        per consumer, so neither a consumer's second subscription that matches the topic nor
        one of a consumer whose process is gone (kill -9: its unsubscriptions are still on their
        way through the channel, however loaded the host) is waited for. Only consumers whose
        table is mapped here are told apart; any other subscription counts. And never fewer
        than the live consumers whose tables take it: the channel's proxy passes a prefix on
        once to a supplier that connects after its subscribers (shm.framed_marker), so two
        consumers of one prefix may show as one subscription. Any thread: a table the reactor
        thread closes meanwhile is of a consumer that is gone."""
        found = self._matching(frame).values()
        live = sum(reader.alive() for reader, _ in found)
        extra = sum(n for _, n in found) - live
        return max(live, subscriptions - extra)

    def close(self) -> None:
        for r in self._readers.values():
            r.close()
        self._readers.clear()
        self._prefixes = []
        self._subs.clear()


class Flow:
    """The frames of one of a supplier's topics in flight toward its keep-all consumers (the
    reactor thread's): the last sequence number of each frame sent, oldest first, back to the
    lowest credit; `room` tells whether one more may go (fewer than `window` frames and
    `events` events in flight toward each)."""

    __slots__ = ("blocked_since", "events", "key", "sent", "stalls", "window")

    def __init__(self, key: int, window: int, events: int = WINDOW_EVENTS) -> None:
        self.key = key
        self.window = window
        self.events = events
        self.sent: list[int] = []
        self.blocked_since: float | None = None
        self.stalls = 0  # times a consumer stopped being waited for (dead, stopped, too slow)

    def room(self, readers: list[CreditReader], supplier: int, now: float, wait: float) -> bool:
        """Whether every consumer of `readers` has fewer than `window` frames in flight (or has
        stopped being waited for: dead, or silent for `wait` seconds of waiting)."""
        sent, key = self.sent, self.key
        mine = (supplier, key)
        lowest: int | None = None
        behind: list[tuple[CreditReader, int]] = []
        for r in readers:
            if r.closed:  # its consumer unsubscribed (a list from before: a replay's thread)
                continue
            due = r.due(supplier, key)
            d = -1 if due is None else due  # none read yet: every frame sent is in flight
            stalled = r.stalled.get(mine)
            if stalled is not None:
                if d == stalled:
                    continue  # not waited for until it returns a credit again
                del r.stalled[mine]
            if lowest is None or d < lowest:
                lowest = d
            in_flight = len(sent) - bisect_left(sent, d)
            if in_flight >= self.window or (in_flight and sent[-1] - d >= self.events):
                behind.append((r, d))
        if lowest is None:
            sent.clear()
        elif sent and sent[0] < lowest:
            del sent[: bisect_left(sent, lowest)]
        if not behind:
            self.blocked_since = None
            return True
        if self.blocked_since is None:
            self.blocked_since = now
        waited_out = now - self.blocked_since >= wait
        for r, d in behind:
            if waited_out or not r.alive():
                r.stalled[mine] = d
                self.stalls += 1
        if waited_out or all(mine in r.stalled for r, _ in behind):
            self.blocked_since = None
            return True
        return False

    def sending(self, last_seq: int) -> None:
        self.sent.append(last_seq)


FREE, WAITED, GAVE_UP = range(3)  # what `TopicCredits.wait_for_room` found


class TopicCredits:
    """The one answer to "may a frame of this topic go now?" for one topic frame: the keep-all
    consumers whose tables credit it (`readers`, found again whenever the supplier's
    subscriptions change: `update`) and its frames in flight toward them (`flow`). A supplier
    asks `room` on its reactor thread and holds frames back meanwhile; the log player's replay
    waits on its own thread (`wait_for_room`). Both within shm.WAIT_KEEP_ALL seconds of blocked
    sending per consumer (`Flow.room`)."""

    __slots__ = ("flow", "frame", "generation", "readers")

    def __init__(self, frame: bytes, type_name: str, window: int) -> None:
        self.frame = frame
        self.flow = Flow(type_key(type_name), window)
        self.readers: list[CreditReader] = []
        self.generation = -1  # of the supplier's subscriptions that `readers` reflects

    def update(self, consumers: KeepAllConsumers, generation: int) -> bool:
        """Find the topic's keep-all consumers again (the subscriptions changed); whether the
        topic gained its first or lost its last (the window is then shared anew:
        `share_window`)."""
        if generation == self.generation:
            return False
        had = bool(self.readers)
        self.readers = consumers.matching(self.frame) if consumers.marker else []
        self.generation = generation
        return had != bool(self.readers)

    def room(self, supplier: int, wait: float = shm.WAIT_KEEP_ALL) -> bool:
        """Whether a frame of `supplier`'s events of this topic may go now (`Flow.room`)."""
        readers = self.readers
        return not readers or self.flow.room(readers, supplier, time.monotonic(), wait)

    def sending(self, first_seq: int, last_seq: int) -> None:
        """A frame of events `first_seq` to `last_seq` goes. Numbers that go back (a replay
        that seeks back or loops) start the count of frames in flight anew."""
        if not self.readers:
            return
        sent = self.flow.sent
        if sent and first_seq <= sent[-1]:
            sent.clear()
        self.flow.sending(last_seq)

    def wait_for_room(
        self, supplier: int, closed: Callable[[], bool], wait: float = shm.WAIT_KEEP_ALL
    ) -> int:
        """Block the calling thread (never a reactor's) until a frame may go: FREE when it
        could at once, WAITED when a credit came, GAVE_UP when a consumer stopped being waited
        for (dead, or `wait` seconds without a credit) or `closed()`."""
        stalls = self.flow.stalls
        pause = 0.0001
        waited = False
        while not self.room(supplier, wait):
            if closed():
                return GAVE_UP
            waited = True
            time.sleep(pause)
            pause = min(pause * 2, 0.002)
        if self.flow.stalls != stalls:
            return GAVE_UP
        return WAITED if waited else FREE


def share_window(topics: Iterable[TopicCredits], window: int) -> None:
    """Split `window` among the topics of `topics` that have keep-all consumers: the channel's
    queue toward a consumer holds the frames of every topic it takes, so the frames in flight
    toward it, all topics together, must stay within one window (each topic at least one)."""
    credited = [c for c in topics if c.readers]
    share = max(1, window // max(1, len(credited)))
    for c in credited:
        c.flow.window = share
