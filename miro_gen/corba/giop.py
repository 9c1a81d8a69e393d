"""GIOP messages (versions 1.0, 1.1 and 1.2): their headers, encoded and decoded.

Every message starts with a 12-byte header: `GIOP`, the version, flags (bit 0: little-endian;
bit 1, from 1.1: more fragments follow), the message type and the size of what follows. CDR
alignment counts from the start of that header. In GIOP 1.2 the body of a Request or Reply starts
at the next multiple of 8 after the message header (when there is a body); in 1.0 and 1.1 it
follows the header at once, so when we send one we pad the service context list to make the
body start at a multiple of 8 too: request and reply bodies are then laid out exactly as
`serialize()` lays out a value after its 4-byte encapsulation header, and go on the wire as they
are.

Decoding raises `GiopError` for anything malformed: the connection answers it with MessageError.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from struct import Struct
from typing import Final, NamedTuple

from miro_gen.exceptions import MARSHAL
from miro_gen.runtime.cdr import BE, LE
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

MAGIC: Final = b"GIOP"
HEADER_SIZE: Final = 12
FLAG_LITTLE: Final = 1
FLAG_MORE: Final = 2
_SIZE = (Struct("<I"), Struct(">I"))

SC_CODE_SETS: Final = 1
SC_MIRO_PAD: Final = 0x4D495200  # "MIR\0": padding that aligns a GIOP 1.0/1.1 body to 8
SC_MIRO_DETAIL: Final = 0x4D495201  # "MIR\1": a system exception's message (UTF-8 string)


class GiopError(Exception):
    """A message that breaks the protocol (answered with MessageError, then the connection is
    closed)."""


class MsgType(enum.IntEnum):
    REQUEST = 0
    REPLY = 1
    CANCEL_REQUEST = 2
    LOCATE_REQUEST = 3
    LOCATE_REPLY = 4
    CLOSE_CONNECTION = 5
    MESSAGE_ERROR = 6
    FRAGMENT = 7


class ReplyStatus(enum.IntEnum):
    NO_EXCEPTION = 0
    USER_EXCEPTION = 1
    SYSTEM_EXCEPTION = 2
    LOCATION_FORWARD = 3
    LOCATION_FORWARD_PERM = 4
    NEEDS_ADDRESSING_MODE = 5


class LocateStatus(enum.IntEnum):
    UNKNOWN_OBJECT = 0
    OBJECT_HERE = 1
    OBJECT_FORWARD = 2
    OBJECT_FORWARD_PERM = 3
    LOC_SYSTEM_EXCEPTION = 4
    LOC_NEEDS_ADDRESSING_MODE = 5


class Header(NamedTuple):
    minor: int  # GIOP 1.minor
    little: bool
    more: bool  # more fragments follow
    type: MsgType
    size: int  # bytes after the header


_TYPES = tuple(MsgType)
_HEADER_FIELDS = Struct("<4sBBBB")


def read_header(data: bytes) -> Header:
    """The 12-byte message header; GiopError if it is not GIOP 1.0 to 1.2."""
    if len(data) < HEADER_SIZE:
        raise GiopError(f"a GIOP header has 12 bytes, not {len(data)}")
    magic, major, minor, flags, kind = _HEADER_FIELDS.unpack_from(data)
    if magic != MAGIC:
        raise GiopError(f"not a GIOP message (it starts {magic!r})")
    if major != 1 or minor > 2:
        raise GiopError(f"GIOP version {major}.{minor} is not supported (1.0 to 1.2 are)")
    if minor == 0 and flags > 1:
        raise GiopError(f"GIOP 1.0 byte-order flag {flags} is neither 0 nor 1")
    if kind > MsgType.FRAGMENT or (kind == MsgType.FRAGMENT and minor == 0):
        raise GiopError(f"unknown GIOP {major}.{minor} message type {kind}")
    little = flags & FLAG_LITTLE
    size = _SIZE[not little].unpack_from(data, 8)[0]
    return Header(minor, bool(little), bool(flags & FLAG_MORE) and minor > 0, _TYPES[kind], size)


# The headers of whole, unfragmented messages seen lately, by their bytes 4 to 12 (version,
# flags, type, size): replies to one operation tend to have one size, so most are found here.
_seen: dict[bytes, Header] = {}


def whole_message_header(data: bytes) -> Header | None:
    """The header of `data` when it is one whole GIOP message, not a fragment (else None:
    to be read the general way); GiopError for a bad header."""
    key = data[4:12]
    h = _seen.get(key)
    if h is None:
        if len(data) < HEADER_SIZE:
            return None
        h = read_header(data)
        if h.more or h.type == MsgType.FRAGMENT:
            return None
        if len(_seen) >= 1024:
            _seen.clear()
        _seen[key] = h
    return h if len(data) == HEADER_SIZE + h.size else None


def _start(minor: int, kind: MsgType) -> CdrOutput:
    out = CdrOutput(bytearray(MAGIC))
    out.raw(bytes((1, minor, FLAG_LITTLE, kind)))
    out.raw(b"\0\0\0\0")  # the size, filled in by _finish
    return out


def _finish(out: CdrOutput) -> bytes:
    _SIZE[LE].pack_into(out.buf, 8, len(out.buf) - HEADER_SIZE)
    return bytes(out.buf)


Contexts = list[tuple[int, bytes]]


def _write_contexts(out: CdrOutput, contexts: Contexts) -> None:
    out.ulong(len(contexts))
    for ident, data in contexts:
        out.ulong(ident)
        out.octets(data, "service context")


def _read_contexts(inp: CdrInput) -> Contexts:
    return [
        (inp.ulong(), inp.octets("service context"))
        for _ in range(inp.length(8, "service contexts"))
    ]


def _padded_contexts(contexts: Contexts, fixed_before: int, fixed_after: int) -> Contexts:
    """`contexts`, plus a padding context if without it the body of a GIOP 1.0/1.1 message would
    not start at a multiple of 8 (`fixed_before`/`fixed_after`: the header's bytes around the
    list, as laid out when the list is empty)."""
    out = CdrOutput(bytearray(fixed_before))
    _write_contexts(out, contexts)
    end = len(out.buf) + (-len(out.buf) & 3)
    return [*contexts, (SC_MIRO_PAD, b"\0\0\0\0")] if (end + fixed_after) % 8 else contexts


# ---- requests -----------------------------------------------------------------------------------


@dataclass
class Request:
    minor: int
    request_id: int
    response_expected: bool
    key: bytes
    operation: str
    contexts: Contexts = field(default_factory=list)
    sync_flags: int = 3  # GIOP 1.2 response_flags (0 oneway, 1 reply on receipt, 3 normal)
    body: int = 0  # offset of the body in the message
    little: bool = True


def encode_request(
    minor: int,
    request_id: int,
    response_expected: bool,
    key: bytes,
    operation: str,
    body: bytes | bytearray | memoryview,
    contexts: Contexts | None = None,
) -> bytes:
    """A Request message whose body (CDR, laid out from a multiple of 8) is `body`."""
    ctx = contexts or []
    out = _start(minor, MsgType.REQUEST)
    if minor >= 2:
        out.ulong(request_id)
        out.octet(3 if response_expected else 0)
        out.raw(b"\0\0\0")
        out.short(0)  # TargetAddress: KeyAddr
        out.octets(key, "object key")
        out.string(operation, "operation")
        _write_contexts(out, ctx)
        if body:
            out.align(8)
    else:
        tail = CdrOutput(bytearray(4))  # what follows the list, laid out from offset 4 mod 8
        tail.ulong(request_id)
        tail.boolean(response_expected)
        if minor == 1:
            tail.raw(b"\0\0\0")
        tail.octets(key, "object key")
        tail.string(operation, "operation")
        tail.octets(b"", "principal")
        # The list ends at a multiple of 4; what follows is aligned to at most 4 within it.
        after = len(tail.buf) - 4
        ctx = _padded_contexts(ctx, HEADER_SIZE, after) if body else ctx
        _write_contexts(out, ctx)
        out.raw(tail.buf[4:])
    out.raw(body)
    return _finish(out)


_ULONG = Struct("<I")
_SIZE_ID = Struct("<II")


class RequestTemplate:
    """The bytes of a Request that stay the same from call to call of one operation on one
    object (all but the request id, the size and the body): a call packs only those."""

    __slots__ = ("after", "before", "fixed", "head")

    def __init__(
        self,
        minor: int,
        response_expected: bool,
        key: bytes,
        operation: str,
        has_body: bool,
        contexts: Contexts | None = None,
    ) -> None:
        probe = encode_request(
            minor, 0, response_expected, key, operation, b"\0" if has_body else b"", contexts
        )
        at = HEADER_SIZE if minor >= 2 else _id_offset(probe)
        self.head = probe[:8]  # GIOP, version, flags, type
        self.before = probe[HEADER_SIZE:at]
        self.after = probe[at + 4 : len(probe) - (1 if has_body else 0)]
        self.fixed = len(self.before) + 4 + len(self.after)

    def message(self, request_id: int, body: bytes | bytearray | memoryview) -> bytes:
        size = self.fixed + len(body)
        if not self.before:  # GIOP 1.2: the request id follows the message header
            return b"".join((self.head, _SIZE_ID.pack(size, request_id), self.after, body))
        return b"".join(
            (self.head, _ULONG.pack(size), self.before, _ULONG.pack(request_id), self.after, body)
        )


def _id_offset(msg: bytes) -> int:
    """Where the request id of a GIOP 1.0/1.1 request is (after the service contexts)."""
    inp = CdrInput(msg, HEADER_SIZE, LE)
    _read_contexts(inp)
    inp.align(4)
    return inp.pos


def decode_request(msg: bytes | bytearray, h: Header) -> Request:
    inp = CdrInput(msg, HEADER_SIZE, LE if h.little else BE)
    try:
        if h.minor >= 2:
            request_id = inp.ulong()
            flags = inp.octet()
            inp.raw(3)
            key = read_target(inp)
            operation = inp.string("operation")
            contexts = _read_contexts(inp)
            if inp.left():
                inp.align(8)
            return Request(
                h.minor, request_id, bool(flags & 1), key, operation, contexts, flags,
                inp.pos, h.little,
            )  # fmt: skip
        contexts = _read_contexts(inp)
        request_id = inp.ulong()
        expected = inp.boolean()
        if h.minor == 1:
            inp.raw(3)
        key = inp.octets("object key")
        operation = inp.string("operation")
        inp.octets("principal")
        flags = 3 if expected else 0
        return Request(
            h.minor, request_id, expected, key, operation, contexts, flags, inp.pos, h.little
        )
    except MARSHAL as e:
        raise GiopError(f"malformed Request header: {e.message}") from None


def request_id_of(head: bytes, h: Header) -> tuple[int, bool]:
    """The request id of a Request and whether it expects a reply, read from its first bytes
    (the rest may be missing: a message refused before it was read); GiopError when they do not
    reach that far."""
    inp = CdrInput(head, HEADER_SIZE, LE if h.little else BE)
    try:
        if h.minor >= 2:
            request_id = inp.ulong()
            return request_id, bool(inp.octet() & 1)
        _read_contexts(inp)
        request_id = inp.ulong()
        return request_id, inp.boolean()
    except MARSHAL:
        raise GiopError("a Request whose first bytes do not hold its request id") from None


def read_target(inp: CdrInput) -> bytes:
    """A GIOP 1.2 TargetAddress, as the object key it names."""
    from miro_gen.corba.ior import IOR, TAG_INTERNET_IOP, IIOPProfile

    mode = inp.short()
    if mode == 0:
        return inp.octets("object key")
    if mode == 1:
        tag = inp.ulong()
        data = inp.octets("profile")
        if tag != TAG_INTERNET_IOP:
            raise MARSHAL(f"the target is a profile of tag {tag}, not IIOP")
        return IIOPProfile.decode(data).key
    if mode == 2:
        index = inp.ulong()
        ior = IOR.read(inp)
        if index >= len(ior.profiles) or ior.profiles[index].tag != TAG_INTERNET_IOP:
            raise MARSHAL(f"the target's profile {index} is not an IIOP profile")
        return IIOPProfile.decode(ior.profiles[index].data).key
    raise MARSHAL(f"unknown target addressing mode {mode}")


# ---- replies -------------------------------------------------------------------------------------


@dataclass
class Reply:
    minor: int
    request_id: int
    status: ReplyStatus
    contexts: Contexts = field(default_factory=list)
    body: int = 0
    little: bool = True


def encode_reply(
    minor: int,
    request_id: int,
    status: ReplyStatus,
    body: bytes | bytearray | memoryview,
    contexts: Contexts | None = None,
) -> bytes:
    ctx = contexts or []
    out = _start(minor, MsgType.REPLY)
    if minor >= 2:
        out.ulong(request_id)
        out.ulong(status)
        _write_contexts(out, ctx)
        if body:
            out.align(8)
    else:
        ctx = _padded_contexts(ctx, HEADER_SIZE, 8) if body else ctx
        _write_contexts(out, ctx)
        out.ulong(request_id)
        out.ulong(status)
    out.raw(body)
    return _finish(out)


def decode_reply(msg: bytes, h: Header) -> Reply:
    inp = CdrInput(msg, HEADER_SIZE, LE if h.little else BE)
    try:
        if h.minor >= 2:
            request_id = inp.ulong()
            status = inp.ulong()
            contexts = _read_contexts(inp)
            if inp.left():
                inp.align(8)
        else:
            contexts = _read_contexts(inp)
            request_id = inp.ulong()
            status = inp.ulong()
        if status > ReplyStatus.NEEDS_ADDRESSING_MODE or (
            h.minor < 2 and status > ReplyStatus.LOCATION_FORWARD
        ):
            raise MARSHAL(f"unknown reply status {status}")
        return Reply(h.minor, request_id, ReplyStatus(status), contexts, inp.pos, h.little)
    except MARSHAL as e:
        raise GiopError(f"malformed Reply header: {e.message}") from None


# ---- the other messages ---------------------------------------------------------------------


def encode_cancel(minor: int, request_id: int) -> bytes:
    out = _start(minor, MsgType.CANCEL_REQUEST)
    out.ulong(request_id)
    return _finish(out)


def encode_locate_request(minor: int, request_id: int, key: bytes) -> bytes:
    out = _start(minor, MsgType.LOCATE_REQUEST)
    out.ulong(request_id)
    if minor >= 2:
        out.short(0)
    out.octets(key, "object key")
    return _finish(out)


def encode_locate_reply(
    minor: int, request_id: int, status: LocateStatus, body: bytes = b""
) -> bytes:
    out = _start(minor, MsgType.LOCATE_REPLY)
    out.ulong(request_id)
    out.ulong(status)
    out.raw(body)
    return _finish(out)


def encode_simple(minor: int, kind: MsgType) -> bytes:
    """CloseConnection or MessageError: a header alone."""
    return _finish(_start(minor, kind))


def decode_request_id(msg: bytes | bytearray, h: Header) -> int:
    """The request id of a CancelRequest, LocateRequest, LocateReply or 1.2 Fragment."""
    try:
        return CdrInput(msg, HEADER_SIZE, LE if h.little else BE).ulong()
    except MARSHAL:
        raise GiopError(f"a {h.type.name} message too short for its request id") from None


def decode_locate_request(msg: bytes | bytearray, h: Header) -> tuple[int, bytes]:
    inp = CdrInput(msg, HEADER_SIZE, LE if h.little else BE)
    try:
        request_id = inp.ulong()
        key = read_target(inp) if h.minor >= 2 else inp.octets("object key")
    except MARSHAL as e:
        raise GiopError(f"malformed LocateRequest: {e.message}") from None
    return request_id, key


def decode_locate_reply(msg: bytes, h: Header) -> tuple[int, LocateStatus, int]:
    """(request id, status, offset of the body)."""
    inp = CdrInput(msg, HEADER_SIZE, LE if h.little else BE)
    try:
        request_id = inp.ulong()
        status = inp.ulong()
        return request_id, LocateStatus(status), inp.pos
    except (MARSHAL, ValueError):
        raise GiopError("malformed LocateReply") from None


def context(contexts: Contexts, ident: int) -> bytes | None:
    return next((data for i, data in contexts if i == ident), None)
