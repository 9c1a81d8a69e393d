"""Large call bodies through shared memory between a caller and a server on one host
(docs/PROTOCOL.md, "Large replies in shared memory", "Large requests in shared memory"): a
pool of slots (`BodyPool`: a server's for its replies, a caller's for its requests), a
caller's mappings of its servers' pools (`SharedReplies`) and a server's of its callers'
(`SharedRequests`), over the rings of `transport.shm`.

A caller that may map this host's segments (`shm.host_key`: same boot, PID namespace and
user) says so in its connection's routing id, which starts with `caller_marker()`; servers of
older versions take it as any routing id. A server answers such a caller's ok replies of
`shm.THRESHOLD` bytes or more with a descriptor of the slot it wrote the body into (reply flag
`frames.SHARED`). A generated stub's thread holds the slot in a lane of its own and decodes
the body in place, and gives the slot back at its next call; any other caller copies the body
out and gives the slot back at once. The slot's generation is checked after the hold (and after
a copy), so that a read later than the lease is a clean error, never torn data. When every
slot is taken, or the caller is not on this host, or is older, the reply travels in its frame
as before.
"""

from __future__ import annotations

import os
import struct
import threading
import time
import weakref
from typing import Final

from miro_gen.exceptions import COMM_FAILURE, MARSHAL, CompletionStatus
from miro_gen.runtime.rpc import Reply, ReplyStatus, system_exception_parts
from miro_gen.transport import shm
from miro_gen.transport.local import is_local_address

SLOTS: Final = 16  # slots of a server's or a caller's pool, by default (MIRO_SHM_CALL_SLOTS)
LEASE: Final = 5.0  # seconds a reply's slot waits for its caller to hold it (MIRO_SHM_LEASE)
# The minor code of the MARSHAL (completed NO) a server answers a request with whose body it
# could not read in its caller's shared memory: the caller sends it again in frames.
UNREADABLE_MINOR: Final = 0x4D470002
SWEEP_EVERY: Final = 1.0  # seconds between a server's looks for callers gone (their pools)


def caller_marker() -> bytes:
    """What begins the routing id of a caller that may take replies in this host's shared
    memory (empty where it may not)."""
    key = shm.host_key()
    return b"\x03shm-" + key + b"\0" if key and shm.enabled() else b""


def server_marker() -> bytes:
    """A server's own routing id when it takes large request bodies in its callers' shared
    memory (empty where it may not): ZeroMQ hands it to every caller in the connection's
    handshake (its `Identity` property), so a caller learns it from its first reply. Text
    without NUL, as such a property is read back."""
    key = shm.host_key()
    return b"miro-shm-requests-" + key if key and shm.enabled() else b""


def takes_requests(identity: str) -> bool:
    """Whether a server whose connection says `identity` (its routing id) takes large request
    bodies in this caller's shared memory."""
    marker = server_marker()
    return bool(marker) and identity.encode("utf-8", "replace") == marker


def routing_id(endpoint: str) -> bytes | None:
    """The routing id a connection to `endpoint` announces itself with: the marker and 8 random
    bytes when the endpoint is on this host and shared memory is on, else None (ZeroMQ's)."""
    marker = caller_marker()
    if not marker or not on_this_host(endpoint):
        return None
    return marker + os.urandom(8)


def on_this_host(endpoint: str) -> bool:
    proto, _, rest = endpoint.partition("://")
    if proto == "ipc":
        return True
    if proto != "tcp":
        return False
    return is_local_address(rest.rpartition(":")[0].strip("[]"))


def lease() -> float:
    try:
        return max(0.0, float(os.environ.get("MIRO_SHM_LEASE", LEASE)))
    except ValueError:
        return LEASE


class BodyPool:
    """Slots for large call bodies: a server's for its replies to callers on its host, or a
    caller's for its requests (`name` "miro-requests"), `slots` (MIRO_SHM_CALL_SLOTS) of up to
    `slot_size` bytes (the largest message), mapped when the first such body is due. Each slot
    is for the one reader its descriptor goes to, until it gives the slot back or its lease
    runs out."""

    def __init__(self, slot_size: int, name: str = "miro-calls") -> None:
        self.name = name
        self.slot_size = slot_size
        self.slots = shm.slot_count("MIRO_SHM_CALL_SLOTS", SLOTS)
        self._marker = caller_marker()
        self._ring: shm.Ring | None = None
        self._lock = threading.Lock()
        self.shared = 0  # bodies sent as descriptors
        self.framed = 0  # large bodies to peers on this host sent in frames: no free slot

    def takes(self, peer: bytes) -> bool:
        """Whether the caller with routing id `peer` may take replies in this pool."""
        return bool(self._marker) and peer.startswith(self._marker)

    def put(self, body: bytes | shm.Encoded) -> bytes | None:
        """`body` (bytes, or an encoder's value, its parts copied straight in: never joined
        first) written into a free slot: the descriptor's bytes; None when no slot is free (or
        the pool is closed, or the body too large for a slot)."""
        ring = self._ring
        if ring is None:
            with self._lock:
                ring = self._ring
                if ring is None:
                    ring = self._ring = shm.Ring(
                        self.slot_size, self.slots, lease=lease(), name=self.name
                    )
        d = ring.put(body, wait=0.0)
        if d is None:
            self.framed += 1
            return None
        self.shared += 1
        return shm.DESCRIPTOR.pack(*d)

    def close(self) -> None:
        with self._lock:
            if self._ring is not None:
                self._ring.close()


class _ThreadMaps:
    """One thread's mappings of its servers' pools, each with a lane of its own, and the reply
    slot it holds until its next call. Unmapped when the thread ends (its locks, and so its
    holds, go with them)."""

    def __init__(self) -> None:
        self.segments = shm.Segments(keep_all=False, replies=True)
        self.held: tuple[shm.Segment, shm.Descriptor] | None = None

    def give_back(self) -> None:
        held, self.held = self.held, None
        if held is not None:
            segment, d = held
            segment.give_back(d)

    def __del__(self) -> None:
        self.give_back()
        self.segments.close()


class SharedReplies:
    """A caller's mappings of its servers' pools, per thread (at most `shm.Segments.MAX` per
    thread: then the oldest is unmapped), unmapped once their server is gone."""

    def __init__(self) -> None:
        self._local = threading.local()
        self._maps: weakref.WeakSet[_ThreadMaps] = weakref.WeakSet()  # every thread's, to close
        self._lock = threading.Lock()
        self.read = 0  # replies read from shared memory
        self.closed = False

    def _mine(self) -> _ThreadMaps:
        maps: _ThreadMaps | None = getattr(self._local, "maps", None)
        if maps is None:
            maps = self._local.maps = _ThreadMaps()
            with self._lock:
                self._maps.add(maps)
        return maps

    def give_back(self) -> None:
        """Return the slot this thread's last reply was read in place from (its next call)."""
        maps: _ThreadMaps | None = getattr(self._local, "maps", None)
        if maps is not None and maps.held is not None:
            maps.give_back()

    def body(
        self, descriptor: bytes, operation: str, in_place: bool, limit: int = 1 << 62
    ) -> bytes | memoryview:
        """The reply body a descriptor names: `in_place`, a read-only view of the slot, which
        this thread holds until its next call (`give_back`: a stub decodes the body first);
        else copied out and the slot given back at once. COMM_FAILURE (completed YES: the call
        ran) when it cannot be read: its server's memory could not be mapped, or the slot was
        written again before it was read (a caller later than the lease), or it is larger
        than `limit`, this caller's maximum message size, which no frame could pass either."""
        try:
            d = shm.Descriptor(*shm.DESCRIPTOR.unpack(descriptor))
        except Exception:
            raise COMM_FAILURE(
                f"{operation}: a malformed shared-memory reply", completed=CompletionStatus.YES
            ) from None
        if d.length > limit:
            raise COMM_FAILURE(
                f"{operation}: the reply is {d.length} bytes, more than the maximum message "
                f"size ({limit}; --max-message-size)",
                completed=CompletionStatus.YES,
            )
        maps = self._mine()
        maps.give_back()
        segment = maps.segments.segment(d)
        if segment is None or not segment.valid(d):
            raise COMM_FAILURE(
                f"{operation}: cannot map the server's shared memory for its reply",
                completed=CompletionStatus.YES,
            )
        data: bytes | memoryview | None
        if in_place and segment.lane >= 0:  # held by this thread's lane: never rewritten
            data = segment.hold(d)
            if data is not None:
                maps.held = (segment, d)
        else:  # no lane of its own: copied out, checked after the copy
            data = segment.copy(d)
        if data is None:
            raise COMM_FAILURE(
                f"{operation}: the reply in shared memory was overwritten before it was read "
                "(read after its lease, MIRO_SHM_LEASE)",
                completed=CompletionStatus.YES,
            )
        self.read += 1
        return data

    def sweep(self) -> None:
        """Unmap this thread's mappings of pools whose servers are gone."""
        maps: _ThreadMaps | None = getattr(self._local, "maps", None)
        if maps is not None:
            if maps.held is not None and not maps.held[0].supplier_alive():
                maps.held = None
            maps.segments.sweep()

    def close(self) -> None:
        with self._lock:
            maps, self._maps = list(self._maps), weakref.WeakSet()
        for m in maps:
            m.held = None
            m.segments.close()


def unreadable(operation: str) -> MARSHAL:
    """What a server answers a request whose body it cannot read in its caller's shared
    memory: the call did not run."""
    return MARSHAL(
        f"{operation}: cannot read the request body in the caller's shared memory",
        UNREADABLE_MINOR,
        CompletionStatus.NO,
    )


def is_unreadable(reply: Reply) -> bool:
    """Whether `reply` is a server's `unreadable` (then the request is sent again in frames)."""
    if reply.status != ReplyStatus.SYSTEM_EXCEPTION or reply.repo_id != MARSHAL._repo_id:
        return False
    parts = system_exception_parts(reply)
    return parts is not None and parts[:2] == (UNREADABLE_MINOR, CompletionStatus.NO)


class SharedRequests:
    """A server's mappings of its callers' pools (at most `shm.Segments.MAX`: then the oldest
    is unmapped), from which the thread that receives a request copies its body out at once,
    giving the slot back; those of callers that are gone are unmapped at the first request
    `SWEEP_EVERY` seconds after the last look."""

    def __init__(self) -> None:
        self._segments = shm.Segments(keep_all=False, replies=True)
        self._lock = threading.Lock()
        self._swept = time.monotonic()
        self.read = 0  # request bodies read from callers' shared memory
        self.refused = 0  # descriptors that could not be read (the caller told: unreadable)

    def body(self, descriptor: bytes, limit: int) -> bytes | None:
        """The request body `descriptor` names, copied out, its generation checked after the
        copy; None when it cannot be read whole: a malformed descriptor, more than `limit`
        bytes (the maximum message size), a caller's memory that cannot be mapped (it is gone,
        or not on this host after all), or a slot written again since (read after its lease)."""
        try:
            d = shm.Descriptor(*shm.DESCRIPTOR.unpack(descriptor))
        except struct.error:
            d = None
        data = None
        if d is not None and d.length <= limit:
            with self._lock:
                now = time.monotonic()
                if now - self._swept >= SWEEP_EVERY:
                    self._swept = now
                    self._segments.sweep()
                segment = self._segments.segment(d)
                if segment is not None and segment.valid(d):
                    data = segment.copy(d)
        if data is None:
            self.refused += 1
        else:
            self.read += 1
        return data

    def close(self) -> None:
        with self._lock:
            self._segments.close()
