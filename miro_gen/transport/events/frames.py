"""The bytes of an event message: the one definition of their layout (docs/PROTOCOL.md, "Event
channels"). Suppliers and consumers (transport.events) and the log tools, which record and
replay events without decoding them (eventlog), all read and write them through this module.

An event message is two ZeroMQ frames, a topic frame and a batch frame, little-endian:

    topic frame    domain (UTF-8) NUL type name (UTF-8) NUL     subscriptions are prefixes of it

    batch frame    offset  size  field
                   0       1     version (VERSION)
                   1       1     flags: 0, or SHM (its one event's payload is a descriptor
                                 of a payload in shared memory: transport.shm)
                   2       2     number of events n (at most MAX_EVENTS)
                   4       8     supplier id (random per supplier)
                   12      32    type hash of the payloads (SHA-256 of the data schema, raw)
                   44            n events:
                   +0      8       sequence number, per supplier and type name
                   +8      8       source time stamp, ns since the Unix epoch (signed)
                   +16     8       publish time, ns since the Unix epoch (signed)
                   +24     4       payload length m
                   +28     m       payload: a CDR encapsulation

`BATCH` packs the frame's header, `EVENT` each event's; the hot paths of transport.events use
them directly. `parse_batch` and `pack_batch` read and write whole frames with the payloads
still encoded. Parsing trusts nothing: what does not parse raises `FrameError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from struct import Struct
from struct import error as StructError
from typing import Final, NamedTuple

VERSION: Final = 1
BATCH: Final = Struct("<BBHQ32s")  # version, flags, count, supplier id, type hash
EVENT: Final = Struct("<QqqI")  # sequence number, stamp ns, publish ns, payload length
LENGTH: Final = Struct("<I")  # the payload length, filled in after the payload is encoded
BATCH_HEADER: Final = BATCH.size  # bytes before a frame's first event
EVENT_HEADER: Final = EVENT.size  # bytes before each payload
LENGTH_AT: Final = BATCH_HEADER + EVENT_HEADER - LENGTH.size  # the first event's payload length
MAX_EVENTS: Final = 0xFFFF  # the count is 16 bits
SHM: Final = 1  # flag: the payload is in shared memory, the frame carries its descriptor


class FrameError(ValueError):
    """A message that is not an event message of this protocol version."""


class RawEvent(NamedTuple):
    """One event, its payload still encoded."""

    domain: str
    type_name: str
    type_hash: str  # hex
    supplier: int
    seq: int
    stamp_ns: int
    publish_ns: int
    data: bytes


def topic(domain: str, type_name: str) -> bytes:
    """The topic frame of events of `type_name` from `domain`."""
    return domain.encode() + b"\0" + type_name.encode() + b"\0"


def split_topic(frame: bytes) -> tuple[str, str]:
    """(domain, type name) of a topic frame."""
    fields = frame.split(b"\0")
    if len(fields) != 3 or fields[2]:
        raise FrameError("malformed topic frame")
    try:
        return fields[0].decode(), fields[1].decode()
    except UnicodeDecodeError as e:
        raise FrameError(f"topic is not UTF-8: {e}") from None


def batch_head(count: int, supplier: int, raw_hash: bytes, flags: int = 0) -> bytes:
    """The header of a batch frame of `count` events with the type hash `raw_hash`."""
    return BATCH.pack(VERSION, flags, count, supplier, raw_hash)


def batch_flags(body: bytes | memoryview) -> int:
    """The flags of a batch frame (0 for a truncated one: `read_batch_head` reports it)."""
    return body[1] if len(body) > 1 else 0


def read_batch_head(body: bytes | memoryview) -> tuple[int, int, bytes]:
    """(number of events, supplier id, raw type hash) of a batch frame's header."""
    try:
        version, _, count, supplier, raw_hash = BATCH.unpack_from(body)
    except StructError:
        raise FrameError("batch header is truncated") from None
    if version != VERSION:
        raise FrameError(f"event version {version} is not supported")
    return count, supplier, raw_hash


def parse_batch(domain: str, type_name: str, body: bytes) -> list[RawEvent]:
    """The events of a batch frame, their payloads copied out as they are."""
    count, supplier, raw_hash = read_batch_head(body)
    if batch_flags(body) & SHM:
        raise FrameError("a shared-memory descriptor, not events")
    type_hash = raw_hash.hex()
    at = BATCH_HEADER
    out = []
    view = memoryview(body)
    for _ in range(count):
        try:
            seq, stamp_ns, publish_ns, n = EVENT.unpack_from(body, at)
        except StructError:
            raise FrameError("event header is truncated") from None
        at += EVENT_HEADER
        if at + n > len(body):
            raise FrameError("event payload is truncated")
        data = bytes(view[at : at + n])
        event = RawEvent(domain, type_name, type_hash, supplier, seq, stamp_ns, publish_ns, data)
        out.append(event)
        at += n
    if at != len(body):
        raise FrameError("trailing bytes after the events")
    return out


def next_due(body: bytes | memoryview) -> tuple[int, int] | None:
    """(supplier id, the sequence number after its last event) of a batch frame, walking over
    the payloads; None for one without events or that does not parse."""
    try:
        count, supplier, _ = read_batch_head(body)
        at, seq = BATCH_HEADER, -1
        for _ in range(count):
            seq, _, _, n = EVENT.unpack_from(body, at)
            at += EVENT_HEADER + n
    except (StructError, FrameError):
        return None
    return None if seq < 0 or at > len(body) else (supplier, seq + 1)


# The layouts of frames whose events all have one payload size, by (count, size): a frame of n
# such events is unpacked by one Struct call instead of a Python step per event.
_UNIFORM: dict[tuple[int, int], Struct] = {}
_UNIFORM_MAX = 256  # layouts kept (frames of camera images and batches of small events)


def batch_payloads(body: bytes | memoryview) -> tuple[bytes, Sequence[bytes]]:
    """(raw type hash, the payloads copied out) of a batch frame: what a forwarder needs,
    without the events' numbers and stamps. Frames whose payloads are all of one size (a type
    of fixed size, a camera's images) take one call of a cached Struct; others a step each."""
    count, _, raw_hash = read_batch_head(body)
    if count == 0:
        if len(body) != BATCH_HEADER:
            raise FrameError("trailing bytes after the events")
        return raw_hash, ()
    stride, rest = divmod(len(body) - BATCH_HEADER, count)
    size = stride - EVENT_HEADER
    if rest == 0 and size >= 0:
        layout = _UNIFORM.get((count, size))
        if layout is None:
            if len(_UNIFORM) >= _UNIFORM_MAX:
                _UNIFORM.clear()
            event = f"{EVENT_HEADER - LENGTH.size}x{LENGTH.format[1:]}{size}s"  # length, payload
            layout = _UNIFORM[count, size] = Struct("<" + event * count)
        fields = layout.unpack_from(body, BATCH_HEADER)
        if fields[0::2].count(size) == count:  # every length is the one assumed
            return raw_hash, fields[1::2]
    payloads = []
    view = memoryview(body)
    at = BATCH_HEADER
    for _ in range(count):
        try:
            n = EVENT.unpack_from(body, at)[3]
        except StructError:
            raise FrameError("event header is truncated") from None
        at += EVENT_HEADER
        if at + n > len(body):
            raise FrameError("event payload is truncated")
        payloads.append(bytes(view[at : at + n]))
        at += n
    if at != len(body):
        raise FrameError("trailing bytes after the events")
    return raw_hash, payloads


def pack_batch(
    supplier: int, type_hash: str, events: Sequence[tuple[int, int, int, bytes]]
) -> bytes:
    """A batch frame of (seq, stamp ns, publish ns, payload) events of one type hash (hex)."""
    if len(events) > MAX_EVENTS:
        raise ValueError(f"at most {MAX_EVENTS} events in a frame")
    parts = [batch_head(len(events), supplier, bytes.fromhex(type_hash))]
    for seq, stamp_ns, publish_ns, data in events:
        parts.append(EVENT.pack(seq, stamp_ns, publish_ns, len(data)))
        parts.append(data)
    return b"".join(parts)
