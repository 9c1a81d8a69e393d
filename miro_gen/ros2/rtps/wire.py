"""The RTPS 2.3 bytes miro's own small RTPS participant writes and reads (no I/O): the message
header, the submessages DATA, HEARTBEAT, ACKNACK, INFO_TS and INFO_DST, parameter lists, and
the discovery data (SPDP participant, SEDP endpoint) a Fast DDS participant needs to match our
endpoints.

Why it exists: Fast DDS (rmw_fastrtps) relates a service reply to its request only through the
reply's inline QoS `related_sample_identity` (PID 0x0083; Fast DDS reads its legacy 0x800f only
from eProsima and RTI participants), which Cyclone DDS can neither write nor expose. Everything
here is little-endian (the E flag set); what is read accepts either byte order.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass, field

PROTOCOL_VERSION = (2, 3)
# A vendor id of no registered vendor: Fast DDS then reads only the standard parameters from us.
VENDOR_ID = b"\x01\xaa"
EPROSIMA = b"\x01\x0f"

# Submessage ids
ACKNACK, HEARTBEAT, GAP, INFO_TS, INFO_SRC, INFO_DST, DATA, DATA_FRAG = (
    0x06, 0x07, 0x08, 0x09, 0x0C, 0x0E, 0x15, 0x16,
)  # fmt: skip

# Entity ids of the builtin endpoints
PARTICIPANT = b"\x00\x00\x01\xc1"
SPDP_WRITER, SPDP_READER = b"\x00\x01\x00\xc2", b"\x00\x01\x00\xc7"
SEDP_PUB_WRITER, SEDP_PUB_READER = b"\x00\x00\x03\xc2", b"\x00\x00\x03\xc7"
SEDP_SUB_WRITER, SEDP_SUB_READER = b"\x00\x00\x04\xc2", b"\x00\x00\x04\xc7"
UNKNOWN_ENTITY = b"\x00\x00\x00\x00"
USER_WRITER_NO_KEY, USER_READER_NO_KEY = 0x03, 0x04

# Builtin endpoint set bits: participant, publications and subscriptions announcers and
# detectors (the peers' writers: which topic an unaddressed DATA is of; their readers: where a
# request goes).
BUILTIN_ENDPOINTS = 0b111111

# Parameter ids
PID_SENTINEL, PID_LEASE_DURATION, PID_TOPIC_NAME, PID_TYPE_NAME = 0x0001, 0x0002, 0x0005, 0x0007
PID_DOMAIN_ID, PID_PROTOCOL_VERSION, PID_VENDOR_ID = 0x000F, 0x0015, 0x0016
PID_RELIABILITY, PID_DURABILITY, PID_USER_DATA = 0x001A, 0x001D, 0x002C
PID_DEFAULT_UNICAST_LOCATOR, PID_METATRAFFIC_UNICAST_LOCATOR = 0x0031, 0x0032
PID_PARTICIPANT_GUID, PID_BUILTIN_ENDPOINT_SET, PID_ENDPOINT_GUID = 0x0050, 0x0058, 0x005A
PID_KEY_HASH, PID_STATUS_INFO, PID_RELATED_SAMPLE_IDENTITY = 0x0070, 0x0071, 0x0083
PID_CUSTOM_RELATED_SAMPLE_IDENTITY = 0x800F

LOCATOR_UDPV4 = 1
UNKNOWN_SEQ = -(1 << 32)  # SEQUENCENUMBER_UNKNOWN: high -1, low 0
PL_CDR_LE = b"\x00\x03\x00\x00"
RELIABLE, BEST_EFFORT = 2, 1
VOLATILE, TRANSIENT_LOCAL = 0, 1


class RtpsError(ValueError):
    """Bytes that are not the RTPS this module reads (the message says what)."""


def spdp_port(domain: int, index: int) -> int:
    """The metatraffic unicast port of participant `index` in `domain` (RTPS 9.6.1.1)."""
    return 7400 + 250 * domain + 10 + 2 * index


@dataclass(frozen=True)
class Guid:
    prefix: bytes  # 12 bytes
    entity: bytes  # 4 bytes

    def __bytes__(self) -> bytes:
        return self.prefix + self.entity

    @classmethod
    def of(cls, raw: bytes) -> Guid:
        if len(raw) != 16:
            raise RtpsError(f"a GUID has 16 bytes, not {len(raw)}")
        return cls(raw[:12], raw[12:])


# -- building -------------------------------------------------------------------------------


def header(prefix: bytes) -> bytes:
    return b"RTPS" + bytes(PROTOCOL_VERSION) + VENDOR_ID + prefix


def _sub(kind: int, flags: int, body: bytes) -> bytes:
    return struct.pack("<BBH", kind, flags | 0x01, len(body)) + body


def _sn(seq: int) -> bytes:
    return struct.pack("<iI", seq >> 32, seq & 0xFFFFFFFF)


def info_dst(prefix: bytes) -> bytes:
    return _sub(INFO_DST, 0, prefix)


def info_ts(seconds: float) -> bytes:
    whole = int(seconds)
    return _sub(INFO_TS, 0, struct.pack("<iI", whole, int((seconds - whole) * 2**32)))


def data(reader: bytes, writer: bytes, seq: int, payload: bytes, inline_qos: bytes = b"") -> bytes:
    """A DATA submessage carrying `payload` (a serialized payload: encapsulation header and
    body; none for a disposal), with `inline_qos` (a parameter list ending with its
    sentinel) when given."""
    flags = (0x04 if payload else 0) | (0x02 if inline_qos else 0)
    body = struct.pack("<HH", 0, 16) + reader + writer + _sn(seq) + inline_qos + payload
    body += b"\x00" * (-len(body) % 4)
    return _sub(DATA, flags, body)


def heartbeat(reader: bytes, writer: bytes, first: int, last: int, count: int) -> bytes:
    return _sub(HEARTBEAT, 0, reader + writer + _sn(first) + _sn(last) + struct.pack("<i", count))


def gap(reader: bytes, writer: bytes, start: int, end: int) -> bytes:
    """A GAP: the numbers from `start` to `end - 1` are not for this reader."""
    return _sub(GAP, 0, reader + writer + _sn(start) + _sn(end) + struct.pack("<I", 0))


def acknack(reader: bytes, writer: bytes, base: int, missing: list[int], count: int) -> bytes:
    """An ACKNACK: everything below `base` received, the numbers in `missing` (each at least
    `base`, less than `base + 256`) wanted again. Final when nothing is missing."""
    bits = max(missing) - base + 1 if missing else 0
    words = [0] * ((bits + 31) // 32)
    for n in missing:
        i = n - base
        words[i // 32] |= 1 << (31 - i % 32)
    body = reader + writer + _sn(base) + struct.pack(f"<I{len(words)}I", bits, *words)
    return _sub(ACKNACK, 0 if missing else 0x02, body + struct.pack("<i", count))


def param(pid: int, value: bytes) -> bytes:
    value += b"\x00" * (-len(value) % 4)
    return struct.pack("<HH", pid, len(value)) + value


def param_list(*params: bytes) -> bytes:
    return b"".join(params) + struct.pack("<HH", PID_SENTINEL, 0)


def _string(text: str) -> bytes:
    raw = text.encode() + b"\x00"
    return struct.pack("<I", len(raw)) + raw


def locator(port: int, address: str = "127.0.0.1") -> bytes:
    ip = bytes(int(p) for p in address.split("."))
    return struct.pack("<iI", LOCATOR_UDPV4, port) + b"\x00" * 12 + ip


def sample_identity(guid: Guid, seq: int) -> bytes:
    return bytes(guid) + _sn(seq)


def related_sample_identity(guid: Guid, seq: int) -> bytes:
    """The inline QoS a reply carries so that Fast DDS relates it to its request."""
    return param_list(param(PID_RELATED_SAMPLE_IDENTITY, sample_identity(guid, seq)))


def spdp_data(
    prefix: bytes, domain: int, meta_port: int, user_port: int, user_data: bytes = b""
) -> bytes:
    """The SPDP participant data (PL_CDR_LE payload) of our participant."""
    params = [
        param(PID_PROTOCOL_VERSION, bytes(PROTOCOL_VERSION)),
        param(PID_VENDOR_ID, VENDOR_ID),
        param(PID_PARTICIPANT_GUID, prefix + PARTICIPANT),
        param(PID_DOMAIN_ID, struct.pack("<I", domain)),
        param(PID_METATRAFFIC_UNICAST_LOCATOR, locator(meta_port)),
        param(PID_DEFAULT_UNICAST_LOCATOR, locator(user_port)),
        param(PID_BUILTIN_ENDPOINT_SET, struct.pack("<I", BUILTIN_ENDPOINTS)),
        param(PID_LEASE_DURATION, struct.pack("<iI", 20, 0)),
    ]
    if user_data:
        params.append(param(PID_USER_DATA, struct.pack("<I", len(user_data)) + user_data))
    return PL_CDR_LE + param_list(*params)


def disposal(guid: Guid) -> bytes:
    """The inline QoS of a DATA saying that the instance of key `guid` (a participant or an
    endpoint, in discovery data) is disposed and unregistered: it is gone."""
    return param_list(param(PID_KEY_HASH, bytes(guid)), param(PID_STATUS_INFO, b"\x00\x00\x00\x03"))


def sedp_data(
    endpoint: Guid, topic: str, type_name: str, reliable: bool = True, user_data: bytes = b""
) -> bytes:
    """The SEDP publication or subscription data (PL_CDR_LE payload) of one of our endpoints
    (volatile; reliable or best effort)."""
    params = [
        param(PID_ENDPOINT_GUID, bytes(endpoint)),
        param(PID_PARTICIPANT_GUID, endpoint.prefix + PARTICIPANT),
        param(PID_TOPIC_NAME, _string(topic)),
        param(PID_TYPE_NAME, _string(type_name)),
        param(PID_RELIABILITY, struct.pack("<iiI", RELIABLE if reliable else BEST_EFFORT, 0, 0)),
        param(PID_DURABILITY, struct.pack("<I", VOLATILE)),
        param(PID_PROTOCOL_VERSION, bytes(PROTOCOL_VERSION)),
        param(PID_VENDOR_ID, VENDOR_ID),
    ]
    if user_data:
        params.append(param(PID_USER_DATA, struct.pack("<I", len(user_data)) + user_data))
    return PL_CDR_LE + param_list(*params)


# -- reading --------------------------------------------------------------------------------


@dataclass
class Submessage:
    """One submessage as read, with the source and time the message's INFO_* put before it."""

    kind: int
    source: bytes  # the sending participant's GUID prefix
    vendor: bytes
    reader: bytes = b""
    writer: bytes = b""
    seq: int = 0
    inline_qos: dict[int, bytes] = field(default_factory=dict)
    payload: bytes = b""
    first: int = 0  # HEARTBEAT
    last: int = 0
    base: int = 0  # ACKNACK
    missing: list[int] = field(default_factory=list)
    final: bool = False
    destination: bytes = b""
    irrelevant: list[int] = field(default_factory=list)  # GAP


def _read_sn(raw: bytes, at: int, order: str) -> int:
    high, low = struct.unpack_from(order + "iI", raw, at)
    return int(high) << 32 | int(low)


def _read_set(raw: bytes, at: int, order: str) -> tuple[int, list[int]]:
    """A SequenceNumberSet at `at`: its base and the numbers whose bits are set."""
    base = _read_sn(raw, at, order)
    (bits,) = struct.unpack_from(order + "I", raw, at + 8)
    if bits > 256 or at + 12 + 4 * ((bits + 31) // 32) > len(raw):
        raise RtpsError(f"a sequence number set of {bits} bits does not fit its submessage")
    words = struct.unpack_from(order + f"{(bits + 31) // 32}I", raw, at + 12)
    return base, [base + i for i in range(bits) if words[i // 32] >> (31 - i % 32) & 1]


def read_params(raw: bytes, order: str = "<") -> dict[int, bytes]:
    """A parameter list's values by id (the last of a repeated id; see `read_param_items`)."""
    return dict(read_param_items(raw, order))


def read_param_items(raw: bytes, order: str = "<") -> Iterator[tuple[int, bytes]]:
    at = 0
    while at + 4 <= len(raw):
        pid, size = struct.unpack_from(order + "HH", raw, at)
        at += 4
        if pid == PID_SENTINEL:
            return
        if at + size > len(raw):
            raise RtpsError(f"parameter 0x{pid:04x} of {size} bytes overruns its list")
        yield pid, raw[at : at + size]
        at += size
    raise RtpsError("a parameter list without its sentinel")


def payload_params(payload: bytes) -> dict[int, bytes]:
    """The parameters of a PL_CDR payload (discovery data)."""
    if len(payload) < 4 or payload[0] != 0 or payload[1] not in (2, 3):
        raise RtpsError("discovery data that is not PL_CDR")
    return read_params(payload[4:], "<" if payload[1] == 3 else ">")


def disposed_key(sub: Submessage) -> bytes | None:
    """The key (the GUID, for discovery data) of a DATA that disposes or unregisters an
    instance (a participant or endpoint gone), else None."""
    status = sub.inline_qos.get(PID_STATUS_INFO, b"")
    if len(status) < 4 or not status[3] & 0x03:
        return None
    key = sub.inline_qos.get(PID_KEY_HASH)
    if key is None and sub.payload:
        params = payload_params(sub.payload)
        key = params.get(PID_ENDPOINT_GUID) or params.get(PID_PARTICIPANT_GUID)
    return key[:16] if key is not None and len(key) >= 16 else None


def read_string(value: bytes) -> str:
    (size,) = struct.unpack_from("<I", value)
    return value[4 : 4 + size].rstrip(b"\x00").decode()


def read_locators(params: list[tuple[int, bytes]], pid: int) -> list[tuple[str, int]]:
    """The UDPv4 (address, port) locators of `pid` in a participant's data."""
    out = []
    for p, value in params:
        if p != pid or len(value) < 24:
            continue
        kind, port = struct.unpack_from("<iI", value)
        if kind == LOCATOR_UDPV4:
            out.append((".".join(str(b) for b in value[20:24]), port))
    return out


def read_message(raw: bytes) -> Iterator[Submessage]:
    """The submessages of one RTPS message (the ones this module reads; others are skipped)."""
    if len(raw) < 20 or raw[:4] != b"RTPS":
        raise RtpsError("not an RTPS message")
    vendor, source = raw[6:8], raw[8:20]
    destination = b""
    at = 20
    while at + 4 <= len(raw):
        kind, flags = raw[at], raw[at + 1]
        order = "<" if flags & 1 else ">"
        (size,) = struct.unpack_from(order + "H", raw, at + 2)
        body_at = at + 4
        end = len(raw) if size == 0 and kind not in (0x01,) else body_at + size
        if end > len(raw):
            raise RtpsError(f"submessage 0x{kind:02x} overruns its message")
        body = raw[body_at:end]
        at = end
        if kind == INFO_SRC and len(body) >= 20:
            source = body[8:20]
        elif kind == INFO_DST and len(body) >= 12:
            destination = body[:12]
        elif kind == DATA and len(body) >= 20:
            (to_qos,) = struct.unpack_from(order + "H", body, 2)
            sub = Submessage(DATA, source, vendor, body[4:8], body[8:12], _read_sn(body, 12, order))
            sub.destination = destination
            q = 4 + to_qos
            if flags & 0x02:
                items = list(read_param_items(body[q:], order))
                sub.inline_qos = dict(items)
                q += sum(4 + len(v) for _, v in items) + 4
            if flags & 0x0C:
                sub.payload = body[q:]
            yield sub
        elif kind == HEARTBEAT and len(body) >= 28:
            sub = Submessage(HEARTBEAT, source, vendor, body[:4], body[4:8])
            sub.first, sub.last = _read_sn(body, 8, order), _read_sn(body, 16, order)
            sub.final, sub.destination = bool(flags & 0x02), destination
            yield sub
        elif kind == GAP and len(body) >= 28:
            sub = Submessage(GAP, source, vendor, body[:4], body[4:8])
            start = _read_sn(body, 8, order)
            base, listed = _read_set(body, 16, order)
            if base - start > 4096:
                raise RtpsError(f"a GAP of {base - start} sequence numbers")
            sub.irrelevant = list(range(start, base)) + listed
            sub.destination = destination
            yield sub
        elif kind == ACKNACK and len(body) >= 24:
            sub = Submessage(ACKNACK, source, vendor, body[:4], body[4:8])
            sub.base, sub.missing = _read_set(body, 8, order)
            sub.final, sub.destination = bool(flags & 0x02), destination
            yield sub
