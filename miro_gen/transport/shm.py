"""Large payloads through shared memory between processes of one host: events (docs/PROTOCOL.md,
"Large events in shared memory") and call replies ("Large replies in shared memory"). A writer's
ring of slots in a memfd segment, and the small descriptor that travels over ZeroMQ instead of
the payload; payloads of THRESHOLD bytes or more take it.

A supplier writes an event's encoded payload into a slot of its ring for the event's type
(`Ring.put`; one ring per supplier and type, so that a consumer's credits cover every write of
the ring it maps) and sends a
descriptor (`Descriptor`, DESCRIPTOR.size bytes) over its usual link; a consumer on the same
host maps the segment through `/proc/<pid>/fd/<fd>` (`Segments.segment`) and reads the payload
in place. The segment is a memfd: it has no name in any file system, and it is gone when the
last process that has it open or mapped is gone, kill -9 included.

No torn data, no slot reused under a reader:

* every slot has a generation, odd while the supplier writes it (a seqlock); a descriptor names
  the generation it was written with, and a reader checks it before and after it reads;
* every consumer process that maps the segment holds a lane in it, claimed with an OFD lock
  (`fcntl`), which the kernel releases when the process dies, so the supplier can tell a live
  lane from a dead one. In its lane the consumer says which write it holds (`hold`: while its
  handler reads the slot, never reused meanwhile) and, for a keep-all consumer, how far it has
  read (`acked`: the credits it returns; the supplier never reuses a slot a keep-all consumer
  has not read: it waits for them, for at most `WAIT_KEEP_ALL` seconds, then goes on without
  the consumers it waited for, as the credits do (`events.credits`): they are not waited for
  again until they read on, and the slots they had not read are rewritten, so they drop those
  events, counted; the others lose none);
* a keep-last consumer that falls a ring behind finds its slot's generation changed and drops
  the event (the oldest goes first), counted in its `dropped`.

A server's ring of replies (`Ring(..., lease=...)`) reserves each slot for the one caller the
reply is for, until that caller says it is done with it (`Segment.copy`, `Segment.give_back`
write the slot's `done`) or the lease runs out with no live lane holding it: a caller that came
later than that finds the generation changed and gets a clean error, never torn data. Such a
ring never waits: when no slot is free the reply travels in its frame.

The pool: `slots` slots (MIRO_SHM_SLOTS, default SLOTS) of up to `slot_size` bytes each (the
largest message allowed); pages are committed as they are first written, so a ring of 1 MiB
events holds slots x 1 MiB.

This module owns the segment's bytes and nothing else: no sockets, no reactor.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import itertools
import mmap
import os
import random
import struct
import sys
import threading
import time
from collections.abc import Callable
from typing import Final, NamedTuple, Protocol

MAGIC: Final = b"MIROSHM1"
THRESHOLD: Final = 64 * 1024  # bytes from which an event's or a reply's payload takes a ring
SLOTS: Final = 16  # slots in a supplier's ring, by default (MIRO_SHM_SLOTS)
LANES: Final = 64  # consumer processes that may map one segment at once
WAIT_KEEP_ALL: Final = 1.0  # seconds a push waits for a keep-all consumer's credit, at most
DEFAULT: Final = "1"  # MIRO_SHM when unset

# The segment: a header, the slots' headers, the lanes, then the slots' data (page-aligned).
_HEAD = struct.Struct("<8sQIIQ")  # magic, segment id, slots, lanes, slot size
_SLOT = struct.Struct("<QQQQ")  # generation (odd: being written), write index, length, done
_LANE = struct.Struct("<QQQQ")  # claimed (1), keep-all (1), acked (writes read), hold (write+1)
_Q = struct.Struct("<Q")
_SLOT_AT = 64
_GEN, _WRITE, _LEN, _DONE = 0, 8, 16, 24  # done: write + 1 once its one reader copied it
_CLAIMED, _KEEP_ALL, _ACKED, _HOLD = 0, 8, 16, 24
_FLOCK = struct.Struct("hhqqi4x")  # struct flock (Linux): type, whence, start, len, pid

# Taken and released between a reader's hold and its check of the slot's generation: a lock's
# atomic instruction orders the store before the load (x86 may reorder them otherwise), so a
# writer that finds no hold has its new generation seen by the check.
_FENCE = threading.Lock()

# The descriptor: supplier pid, its fd of the segment, segment id, slot, generation, write
# index, payload length.
DESCRIPTOR: Final = struct.Struct("<IIQIQQQ")


class Encoded(Protocol):
    """An encoded value not yet put together (runtime.cdr.Encoder)."""

    @property
    def size(self) -> int: ...

    def copy_into(self, out: memoryview) -> int: ...


# The keep-all consumers whose lanes a put waits for: a count, or a function that tells it as
# the subscriptions are now (asked again while the put waits: one may go meanwhile).
KeepAll = int | Callable[[], int]


class Descriptor(NamedTuple):
    pid: int
    fd: int
    segment: int
    slot: int
    generation: int
    write: int
    length: int


def available() -> bool:
    """Whether this platform has what the ring needs (Linux: memfd, OFD locks, /proc)."""
    return sys.platform.startswith("linux") and hasattr(os, "memfd_create")


def enabled() -> bool:
    """Whether large events take the ring: on by default, MIRO_SHM=0 turns it off (any other
    value than 1 does)."""
    return available() and os.environ.get("MIRO_SHM", DEFAULT) == "1"


@functools.cache
def host_key() -> bytes:
    """Who can map a segment of this process: same boot, same PID namespace (the pid in a
    descriptor means the same process), same user (may open /proc/<pid>/fd)."""
    try:
        with open("/proc/sys/kernel/random/boot_id", "rb") as f:
            boot = f.read().strip()
        pidns = os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        return b""
    # The values themselves, not a digest of them: hashlib would load OpenSSL into every
    # process that calls (3.4 MB; issue 30), and none of the three is a secret.
    return b"%s-%x-%x" % (boot.replace(b"-", b"")[:16], pidns, os.getuid())


_MARKERS: Final = b"\x01shm-"  # what every topic marker starts with


def topic_marker() -> bytes:
    """What precedes the topic of an event sent as a descriptor, and a consumer's subscription
    to them: consumers of other hosts (users, PID namespaces) never match it."""
    key = host_key()
    return _MARKERS + key + b"\0" if key else b""


def framed_marker() -> bytes:
    """What precedes the second subscription to a prefix of a subscriber that takes large
    events only in frames (shared memory off or unavailable, a raw tap): the marker of no host.

    A supplier cannot count the subscribers of a prefix: the channel's proxy (XSUB) passes a
    prefix on once to a supplier that connects after its subscribers, and an unsubscription
    only when the prefix's last subscriber goes. So a subscriber of this host that maps rings
    and one that needs frames, both subscribed to the same prefix, look like one; a subscriber
    that needs frames says so with a subscription of its own, as those of other hosts do with
    their host's marker."""
    return _MARKERS + b"\0"


def marked(subscription: bytes) -> tuple[bytes, bytes] | None:
    """(marker, prefix) of a subscription after a topic marker (of this host, of another, or
    `framed_marker`); None for any other subscription."""
    if not subscription.startswith(_MARKERS):
        return None
    end = subscription.find(b"\0", len(_MARKERS))
    return None if end < 0 else (subscription[: end + 1], subscription[end + 1 :])


def keep_all_marker() -> bytes:
    """What precedes a keep-all consumer's third subscription to a prefix, which no frame ever
    matches: it tells suppliers how many keep-all consumers to expect lanes of, so that they
    wait for one that has not mapped the ring yet instead of lapping it."""
    key = host_key()
    return b"\x02shm-" + key + b"\0" if key else b""


def slot_count(variable: str = "MIRO_SHM_SLOTS", default: int = SLOTS) -> int:
    try:
        return max(2, int(os.environ.get(variable, default)))
    except ValueError:
        return default


def holds_open(pid: int, their_fd: int, fd: int) -> bool:
    """Whether process `pid` still has, as its descriptor `their_fd`, the file this process
    has open as `fd` (a segment or table it made and we mapped): False once it is gone, or
    once we closed `fd` (another thread may have, meanwhile)."""
    try:
        info = os.stat(f"/proc/{pid}/fd/{their_fd}")
        mine = os.fstat(fd)
    except OSError:
        return False
    return (info.st_dev, info.st_ino) == (mine.st_dev, mine.st_ino)


def unmap(fd: int, mapping: mmap.mmap, *views: memoryview) -> None:
    """Let a mapping go: release its `views`, unmap it and close `fd`, its file, each step
    whatever the one before did (a view still exported keeps the mapping until it goes). The
    one way segments and credit tables (`events.credits`) are closed."""
    for view in views:
        with contextlib.suppress(Exception):
            view.release()
    with contextlib.suppress(Exception):
        mapping.close()
    with contextlib.suppress(OSError):
        os.close(fd)


def _lock(fd: int, kind: int, start: int, cmd: int) -> int:
    """An OFD lock request of one byte at `start`; the lock type the kernel answers."""
    answer = fcntl.fcntl(fd, cmd, _FLOCK.pack(kind, os.SEEK_SET, start, 1, 0))
    return int(_FLOCK.unpack(answer)[0])


def _layout(slots: int, lanes: int) -> tuple[int, int]:
    """(offset of the lanes, offset of the first slot's data)."""
    lanes_at = _SLOT_AT + slots * _SLOT.size
    data_at = lanes_at + lanes * _LANE.size
    return lanes_at, -(-data_at // mmap.PAGESIZE) * mmap.PAGESIZE


class Ring:
    """A writer's ring: `put` writes a payload into a free slot and returns its descriptor.
    Thread-safe. With a `lease` (seconds), each slot is for one reader, who returns it (`done`),
    and slots are taken lowest first (the same few pages stay warm)."""

    def __init__(
        self,
        slot_size: int,
        slots: int | None = None,
        lanes: int = LANES,
        *,
        lease: float | None = None,
        name: str = "miro-events",
    ) -> None:
        self.slots = slot_count() if slots is None else slots
        self.lease = lease
        self._written_at = [0.0] * self.slots
        self.lanes = lanes
        self.slot_size = -(-slot_size // mmap.PAGESIZE) * mmap.PAGESIZE
        self.segment_id = random.getrandbits(63)
        self._lanes_at, self._data_at = _layout(self.slots, lanes)
        self._lanes_struct = struct.Struct(f"<{lanes * 4}Q")
        size = self._data_at + self.slots * self.slot_size
        self.fd = os.memfd_create(name, os.MFD_CLOEXEC)
        os.ftruncate(self.fd, size)
        self._map = mmap.mmap(self.fd, size)
        self._mem = memoryview(self._map)
        _HEAD.pack_into(self._mem, 0, MAGIC, self.segment_id, self.slots, lanes, self.slot_size)
        self._writes = 0  # writes so far; write w goes to a slot free for it
        self._slot_write = [-1] * self.slots  # the write each slot holds
        self._next = 0
        self._lock = threading.Lock()
        self.waited = 0  # puts that waited for a keep-all consumer's credit
        # lane -> the `acked` it was given up at (waited for `wait` seconds): not waited for
        # again until it reads on (its acked changes), as the credits' stalled consumers
        self._stalled: dict[int, int] = {}
        # (keep-all consumers subscribed, their lanes here) when a put last waited out for the
        # lanes still missing (a consumer that never maps the ring, or whose subscription
        # outlived it): as they were then, they are not waited for again
        self._missing_stalled: tuple[int, int] | None = None
        self.stalls = 0  # times a keep-all consumer stopped being waited for
        self.closed = False

    def put(
        self, payload: bytes | Encoded, keep_all: KeepAll = 0, wait: float = WAIT_KEEP_ALL
    ) -> Descriptor | None:
        """Write `payload` (bytes, or an encoder's value copied straight in) into a slot; its
        descriptor, or None when no slot frees up within `wait` seconds (every slot held, or a
        keep-all consumer subscribed has not mapped the ring) or it does not fit. Keep-all
        consumers behind are waited for that long, then given up (`_give_up`). `keep_all`:
        keep-all consumers subscribed, whose lanes a reused slot waits for (a function: asked
        again while the put waits, so that one that has gone meanwhile is not waited for to the
        end)."""
        n = len(payload) if isinstance(payload, bytes) else payload.size
        if n > self.slot_size:
            return None
        with self._lock:
            if self.closed:
                return None
            taken = self._take_slot(wait, keep_all)
            if taken is None:
                return None
            slot, gen = taken
            w = self._writes
            self._writes += 1
            self._slot_write[slot] = w
            if self.lease is not None:
                self._written_at[slot] = time.monotonic()
            at = _SLOT_AT + slot * _SLOT.size
            mem = self._mem
            _Q.pack_into(mem, at + _WRITE, w)
            _Q.pack_into(mem, at + _LEN, n)
            start = self._data_at + slot * self.slot_size
            if isinstance(payload, bytes):
                mem[start : start + n] = payload
            else:
                payload.copy_into(mem[start : start + n])
            _Q.pack_into(mem, at + _GEN, gen + 1)
            return Descriptor(os.getpid(), self.fd, self.segment_id, slot, gen + 1, w, n)

    def _take_slot(self, wait: float, keep_all: KeepAll) -> tuple[int, int] | None:
        """A free slot (`_free_slot`) marked as being written: (slot, its odd generation).

        A reader holds a write, then checks the generation; the ring checks the holds, then
        writes: a reader that holds the slot's write between the two passed its check, and its
        handler would read the slot while it is rewritten (with zero_copy, unseen). So the ring
        marks the slot first and looks at the holds again after (each side writes, then reads
        what the other wrote): a reader that came meanwhile keeps it, and the ring takes
        another."""
        mem = self._mem
        while True:
            slot = self._free_slot(wait, keep_all)
            if slot is None:
                return None
            at = _SLOT_AT + slot * _SLOT.size
            gen = _Q.unpack_from(mem, at + _GEN)[0]
            _Q.pack_into(mem, at + _GEN, gen + 1)  # odd: being written
            with _FENCE:  # (a locked instruction: the store is seen before the holds are read)
                pass
            if self._reusable(self._slot_write[slot]) != 1:
                return slot, gen + 1
            _Q.pack_into(mem, at + _GEN, gen)  # held meanwhile: as it was, for its reader

    def _free_slot(self, wait: float, keep_all: KeepAll) -> int | None:
        """The next slot in turn that no consumer holds and every keep-all consumer has read
        (waiting up to `wait` seconds for their credits, and for the lanes of `keep_all`
        consumers to be there; then going on without those waited for, once)."""
        deadline = None
        pause = 0.0001
        while True:
            blocked = False
            behind = -1  # the write a keep-all consumer's lane has not read yet
            missing: bool | None = None  # a keep-all consumer's lane is not there yet
            first = self._next if self.lease is None else 0
            for k in range(self.slots):
                slot = (first + k) % self.slots
                w = self._slot_write[slot]
                state = self._reusable(w) if self.lease is None else self._returned(slot, w)
                if state == 0 and w >= 0 and keep_all:
                    if missing is None:  # (after _reusable: the lanes of the dead freed)
                        expected = keep_all() if callable(keep_all) else keep_all
                        lanes = self._keep_all_lanes()
                        missing = lanes < expected and (expected, lanes) != self._missing_stalled
                    if missing:
                        state = 2  # a keep-all consumer has yet to map the ring: not past it
                if state == 0:
                    self._next = (slot + 1) % self.slots
                    return slot
                if state == 2:
                    blocked = True  # a keep-all consumer has not read it: wait, in order
                    behind = -1 if missing else w
                    break
            if deadline is None:
                deadline = time.monotonic() + wait
            if time.monotonic() >= deadline:
                if behind >= 0 and self._give_up(behind):
                    continue  # the slot is free of them now (unless a reader holds it)
                if missing:  # waited out too: not waited for again until either count changes
                    self._missing_stalled = (expected, lanes)
                    self.stalls += 1
                    continue
                return None
            if blocked:
                self.waited += 1
            time.sleep(pause)
            pause = min(pause * 2, 0.005)

    def _lane_words(self) -> list[int]:
        """Every lane's words, read in one pass (a walk lane by lane cost 13-21 us, about 2%
        of a 1 MiB put, and the ring reads them for each slot it looks at): lane k's claimed,
        keep-all, acked and hold are items 4k to 4k + 3."""
        return list(self._lanes_struct.unpack_from(self._mem, self._lanes_at))

    def _keep_all_lanes(self) -> int:
        words = self._lane_words()
        return sum(itertools.compress(words[1::4], words[::4]))  # keep-all (1) of the claimed

    def _reusable(self, w: int) -> int:
        """0: a slot last written with write `w` may be written again; 1: a live consumer
        holds it; 2: a live keep-all consumer (not given up) has not read it yet."""
        if w < 0:
            return 0
        words, stalled = self._lane_words(), self._stalled
        for lane in itertools.compress(range(self.lanes), words[::4]):  # the claimed lanes
            _, keep_all, acked, hold = words[4 * lane : 4 * lane + 4]
            if keep_all and lane in stalled:
                if stalled[lane] != acked:
                    del stalled[lane]  # it reads on: waited for again
                elif hold != w + 1:
                    continue  # given up and not read on since: not waited for
            if hold == w + 1 or (keep_all and acked <= w):
                base = self._lanes_at + lane * _LANE.size
                if not self._alive(base):
                    _LANE.pack_into(self._mem, base, 0, 0, 0, 0)  # its process died: free it
                    stalled.pop(lane, None)
                    continue
                return 1 if hold == w + 1 else 2
        return 0

    def _give_up(self, w: int) -> bool:
        """Stop waiting for the keep-all consumers that have not read write `w` after a put
        waited its time for them (stopped, hung, or too slow): the ring goes on without them
        until they read on. Whether there was any."""
        words = self._lane_words()
        found = False
        for lane in itertools.compress(range(self.lanes), words[::4]):  # the claimed lanes
            _, keep_all, acked, _ = words[4 * lane : 4 * lane + 4]
            if keep_all and acked <= w and lane not in self._stalled:
                self._stalled[lane] = acked
                self.stalls += 1
                found = True
        return found

    def _returned(self, slot: int, w: int) -> int:
        """For a ring with a lease: 0 when the slot last written with write `w` has been
        copied by its reader, or its lease has run out and no live reader holds it; else 1."""
        if w < 0:
            return 0
        done = _Q.unpack_from(self._mem, _SLOT_AT + slot * _SLOT.size + _DONE)[0]
        if done == w + 1:
            return 0
        assert self.lease is not None
        if time.monotonic() - self._written_at[slot] < self.lease:
            return 1
        return self._reusable(w)

    def _alive(self, base: int) -> bool:
        """Whether a process still holds the lane at `base` (its OFD lock)."""
        try:
            return _lock(self.fd, fcntl.F_WRLCK, base, fcntl.F_OFD_GETLK) != fcntl.F_UNLCK
        except OSError:
            return True

    def close(self) -> None:
        with self._lock:
            if self.closed:
                return
            self.closed = True
            unmap(self.fd, self._map, self._mem)


class Segment:
    """A consumer's mapping of a supplier's segment, and its lane in it."""

    def __init__(
        self, pid: int, fd: int, segment_id: int, keep_all: bool, first: int, lane: bool = True
    ) -> None:
        """`lane`: a lane is needed (events); else, when every lane is taken, the mapping reads
        without one (a reply's reader: its slot's lease and the seqlock are enough)."""
        self.pid = pid
        self._need_lane = lane
        self.closed = False  # (events still queued may name it: they are then dropped)
        self.supplier_fd = fd
        self.segment_id = segment_id
        self.fd = os.open(f"/proc/{pid}/fd/{fd}", os.O_RDWR | os.O_CLOEXEC)
        try:
            size = os.fstat(self.fd).st_size
            self._map = mmap.mmap(self.fd, size)
        except (OSError, ValueError):
            os.close(self.fd)
            raise
        self.mem = memoryview(self._map)
        self._readonly = self.mem.toreadonly()
        try:
            magic, sid, slots, lanes, slot_size = _HEAD.unpack_from(self.mem, 0)
            if magic != MAGIC or sid != segment_id:
                raise OSError("not the segment the descriptor names")
            self.slots, self.slot_size = slots, slot_size
            self._lanes_at, self._data_at = _layout(slots, lanes)
            if self._data_at + slots * slot_size > size:
                raise OSError("segment smaller than its header says")
            self.acked = first
            self.lane = self._claim(lanes, keep_all)
        except Exception:
            self.close()
            raise

    def _claim(self, lanes: int, keep_all: bool) -> int:
        for lane in range(lanes):
            base = self._lanes_at + lane * _LANE.size
            try:
                _lock(self.fd, fcntl.F_WRLCK, base, fcntl.F_OFD_SETLK)
            except OSError:
                continue  # another live process has it
            # Credits from the first write seen on: those before are not waited for.
            _LANE.pack_into(self.mem, base, 1, int(keep_all), self.acked, 0)
            self._lane_mem, self._lane_base = self.mem, base
            return lane
        if not self._need_lane:  # holds go to memory of its own, which nobody reads
            self._lane_mem, self._lane_base = memoryview(bytearray(_LANE.size)), 0
            return -1
        raise OSError("every lane of the segment is taken")

    def hold(self, d: Descriptor) -> memoryview | None:
        """The payload of `d`, read-only, held (never rewritten) until `release`; None when its
        slot has been written again since (the descriptor is stale), or the mapping is closed."""
        if self.closed:
            return None
        _Q.pack_into(self._lane_mem, self._lane_base + _HOLD, d.write + 1)
        with _FENCE:  # a locked instruction: the hold is visible before the generation is read
            pass
        if not self.current(d):
            _Q.pack_into(self._lane_mem, self._lane_base + _HOLD, 0)
            return None
        start = self._data_at + d.slot * self.slot_size
        return self._readonly[start : start + d.length]

    def current(self, d: Descriptor) -> bool:
        """Whether the slot of `d` still holds its write (checked again after a read: a
        changed generation means the read may be torn)."""
        if self.closed:
            return False
        at = _SLOT_AT + d.slot * _SLOT.size
        gen, w, n, _ = _SLOT.unpack_from(self.mem, at)
        return bool(gen == d.generation and w == d.write and n == d.length)

    def valid(self, d: Descriptor) -> bool:
        return bool(0 <= d.slot < self.slots and d.length <= self.slot_size)

    def release(self, d: Descriptor, keep_all: bool) -> None:
        """Done with `d`: its slot may be reused (a keep-all consumer's credit with it)."""
        if self.closed:
            return
        _Q.pack_into(self._lane_mem, self._lane_base + _HOLD, 0)
        if keep_all:
            self.ack(d.write + 1)

    def ack(self, acked: int) -> None:
        if acked > self.acked and not self.closed:
            self.acked = acked
            _Q.pack_into(self._lane_mem, self._lane_base + _ACKED, acked)

    def copy(self, d: Descriptor) -> bytes | None:
        """The payload of `d` copied out, and its slot returned to the writer (a reply's one
        reader); None when the slot was written again before or during the copy."""
        view = self.hold(d)
        if view is None:
            return None
        try:
            data = view.tobytes()
        finally:
            view.release()
        ok = self.current(d)
        self.release(d, False)  # (the hold goes first: a slot done is never still held)
        if ok:
            _Q.pack_into(self.mem, _SLOT_AT + d.slot * _SLOT.size + _DONE, d.write + 1)
        return data if ok else None

    def give_back(self, d: Descriptor) -> None:
        """Done with the reply `d` held in place (`hold`): its slot goes back to the writer."""
        if self.closed:
            return
        self.release(d, False)  # (the hold goes first: the writer, finding the slot done,
        # would otherwise find it held too and look again until the hold is gone)
        _Q.pack_into(self.mem, _SLOT_AT + d.slot * _SLOT.size + _DONE, d.write + 1)

    def supplier_alive(self) -> bool:
        """Whether the supplier still has its segment open (its process is alive)."""
        return holds_open(self.pid, self.supplier_fd, self.fd)

    def close(self) -> None:
        self.closed = True
        unmap(self.fd, self._map, self._readonly, self.mem)


class Segments:
    """A consumer process's mappings, one per supplier segment it has seen (at most MAX)."""

    MAX = 64

    def __init__(self, keep_all: bool, replies: bool = False) -> None:
        """`replies`: a caller's mappings of servers' pools, which need no lane and make room
        for a new one by unmapping the oldest."""
        self.keep_all = keep_all
        self.replies = replies
        self._by_id: dict[int, Segment] = {}
        self.refused = 0  # descriptors whose segment could not be mapped

    def segment(self, d: Descriptor) -> Segment | None:
        seg = self._by_id.get(d.segment)
        if seg is not None:
            return seg
        self.sweep()
        if len(self._by_id) >= self.MAX:
            if not self.replies:
                return None
            self._by_id.pop(next(iter(self._by_id))).close()
        try:
            seg = Segment(d.pid, d.fd, d.segment, self.keep_all, d.write, not self.replies)
        except (OSError, ValueError, struct.error):
            self.refused += 1
            return None
        self._by_id[d.segment] = seg
        return seg

    def sweep(self) -> int:
        """Unmap the segments of suppliers that are gone; how many."""
        gone = [s for s in self._by_id.values() if not s.supplier_alive()]
        for s in gone:
            del self._by_id[s.segment_id]
            s.close()
        return len(gone)

    def close(self) -> None:
        for s in self._by_id.values():
            s.close()
        self._by_id.clear()
