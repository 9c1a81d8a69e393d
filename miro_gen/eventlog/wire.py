"""Event frames as raw bytes: what a recorder reads and a player writes.

The transport's consumers decode payloads into generated types; a recorder must keep the CDR
bytes as they came, and a player must send them again with their recorded stamps and sequence
numbers. This module reads and writes the batch frame of docs/PROTOCOL.md ("Event channels")
without decoding payloads. Parsing trusts nothing: a frame that does not parse raises
`FrameError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from struct import Struct
from struct import error as StructError
from typing import NamedTuple

VERSION = 1
_BATCH = Struct("<BBHQ32s")  # version, flags, count, supplier id, type hash
_EVENT = Struct("<QqqI")  # sequence number, stamp ns, publish ns, payload length
MAX_EVENTS = 0xFFFF  # the count is 16 bits
EVENT_HEADER = _EVENT.size  # bytes before each payload
BATCH_HEADER = _BATCH.size  # bytes before a frame's first event


class FrameError(ValueError):
    """A message that is not an event frame of this protocol version."""


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


def split_topic(frame: bytes) -> tuple[str, str]:
    """(domain, type name) of a topic frame `domain\\0type\\0`."""
    fields = frame.split(b"\0")
    if len(fields) != 3 or fields[2]:
        raise FrameError("malformed topic frame")
    try:
        return fields[0].decode(), fields[1].decode()
    except UnicodeDecodeError as e:
        raise FrameError(f"topic is not UTF-8: {e}") from None


def parse_batch(domain: str, type_name: str, body: bytes) -> list[RawEvent]:
    """The events of a batch frame."""
    try:
        version, _, count, supplier, raw_hash = _BATCH.unpack_from(body)
    except StructError:
        raise FrameError("batch header is truncated") from None
    if version != VERSION:
        raise FrameError(f"event version {version} is not supported")
    type_hash = raw_hash.hex()
    at = _BATCH.size
    out = []
    view = memoryview(body)
    for _ in range(count):
        try:
            seq, stamp_ns, publish_ns, n = _EVENT.unpack_from(body, at)
        except StructError:
            raise FrameError("event header is truncated") from None
        at += _EVENT.size
        if at + n > len(body):
            raise FrameError("event payload is truncated")
        out.append(
            RawEvent(
                domain,
                type_name,
                type_hash,
                supplier,
                seq,
                stamp_ns,
                publish_ns,
                bytes(view[at : at + n]),
            )
        )
        at += n
    if at != len(body):
        raise FrameError("trailing bytes after the events")
    return out


def pack_batch(
    supplier: int, type_hash: str, events: Sequence[tuple[int, int, int, bytes]]
) -> bytes:
    """A batch frame of (seq, stamp ns, publish ns, payload) events of one type hash."""
    if len(events) > MAX_EVENTS:
        raise ValueError(f"at most {MAX_EVENTS} events in a frame")
    parts = [_BATCH.pack(VERSION, 0, len(events), supplier, bytes.fromhex(type_hash))]
    for seq, stamp_ns, publish_ns, data in events:
        parts.append(_EVENT.pack(seq, stamp_ns, publish_ns, len(data)))
        parts.append(data)
    return b"".join(parts)
