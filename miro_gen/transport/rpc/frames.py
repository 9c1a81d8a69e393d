"""The frames of remote calls on the wire (docs/PROTOCOL.md has the layout and its reasons).

A request is two ZeroMQ frames, a header and a CDR body; so is a reply. Headers are little-endian
and start with the protocol version, so that a peer speaking another version (or not speaking
this protocol at all) is recognised and its frames dropped, never misread. Parsing never trusts
its input: every length is checked against the bytes present, and a frame that does not parse
raises `FrameError` (the caller logs and drops it).
"""

from __future__ import annotations

import enum
from struct import Struct
from struct import error as StructError
from typing import Final, NamedTuple, Protocol

from miro_gen.runtime.rpc import ReplyStatus as Status

VERSION: Final = 1
ZERO_COPY_MIN: Final = 64 * 1024  # bytes of a body from which it is sent without a copy
MAX_NAME: Final = 0xFFFF  # bytes of an object key, operation name or repository id
SHARED: Final = (
    1  # request or reply flag: the body frame is a descriptor of the body in shared memory
)


class Kind(enum.IntEnum):
    REQUEST = 1  # a reply is expected
    ONEWAY = 2  # no reply
    REPLY = 3


class Received(Protocol):
    """A received ZeroMQ frame (`zmq.Frame`): its bytes copied, or a view over its buffer."""

    @property
    def bytes(self) -> bytes: ...
    @property
    def buffer(self) -> memoryview: ...
    def __len__(self) -> int: ...


def body_of(frame: Received) -> bytes | memoryview:
    """A received body: from ZERO_COPY_MIN bytes on, a read-only view over the frame's buffer
    (it keeps the frame alive), so that decoding copies each byte at most once (the `bytes`
    of a sequence of octets); below, its bytes (a copy is cheaper than a view there)."""
    if len(frame) < ZERO_COPY_MIN:
        return frame.bytes
    return frame.buffer.toreadonly()


class FrameError(ValueError):
    """A frame that is not a valid frame of this protocol version."""


# version, kind, flags, reserved, timeout ms, request id | key length (then key, op length, op)
_REQUEST: Final = Struct("<BBBBIQH")
_REQUEST_PREFIX: Final = Struct("<BBBBIQ")  # the part that changes from call to call
# version, kind, status, flags, reserved, request id | repository id length (then the id)
_REPLY: Final = Struct("<BBBBIQH")
_U16: Final = Struct("<H")
_OK: Final = Status.OK
_OK_REPLY: Final = bytes((VERSION, Kind.REPLY, Status.OK, 0))  # version, kind, status, flags
_SHARED_REPLY: Final = bytes((VERSION, Kind.REPLY, Status.OK, SHARED))
_REQUEST_KIND: Final = int(Kind.REQUEST)
_ONEWAY_KIND: Final = int(Kind.ONEWAY)


class Request(NamedTuple):
    request_id: int
    key: bytes
    operation: str
    timeout_ms: int = 0  # how long the caller waits (0: no limit); late requests are skipped
    oneway: bool = False
    shared: bool = False  # the body frame is a descriptor of the body in the caller's pool


class Reply(NamedTuple):
    request_id: int
    status: Status
    repo_id: str = ""


def encode_request(r: Request) -> bytes:
    tail = request_tail(r.key, r.operation)
    return request_header(tail, r.request_id, r.timeout_ms, r.oneway, r.shared)


def request_tail(key: bytes, operation: str) -> bytes:
    """The end of a request header, from the key length on: the same for every call of one
    operation of one object, so callers build it once (`request_header` adds the rest)."""
    op = operation.encode("utf-8")
    if len(key) > MAX_NAME or len(op) > MAX_NAME:
        raise ValueError("object key and operation name are limited to 65535 bytes")
    return _U16.pack(len(key)) + key + _U16.pack(len(op)) + op


def request_header(
    tail: bytes, request_id: int, timeout_ms: int, oneway: bool = False, shared: bool = False
) -> bytes:
    """A request header: `encode_request` with the tail built beforehand."""
    kind = _ONEWAY_KIND if oneway else _REQUEST_KIND
    flags = SHARED if shared else 0
    return _REQUEST_PREFIX.pack(VERSION, kind, flags, 0, timeout_ms, request_id) + tail


def decode_request(frame: bytes) -> Request:
    try:
        version, kind, flags, _, timeout_ms, request_id = _REQUEST_PREFIX.unpack_from(frame)
        if version != VERSION:
            _check_version(version)
        if kind != _REQUEST_KIND and kind != _ONEWAY_KIND:
            raise FrameError(f"expected a request, got frame kind {kind}")
        tail = frame[_REQUEST_PREFIX.size :]
        target = _targets.get(tail)
        if target is None:
            target = _target(tail)
    except (StructError, UnicodeDecodeError) as e:
        raise FrameError(f"malformed request header: {e}") from None
    oneway = kind == _ONEWAY_KIND
    return Request(request_id, target[0], target[1], timeout_ms, oneway, bool(flags & SHARED))


_targets: dict[bytes, tuple[bytes, str]] = {}  # request tails seen, decoded (a few per object)
MAX_TARGETS: Final = 4096
# Only short tails are remembered: real keys and operation names are a few dozen bytes, and a
# peer's made-up 64 KB names must not fill the table with gigabytes (4096 x 128 KB).
MAX_TARGET_BYTES: Final = 256


def _target(tail: bytes) -> tuple[bytes, str]:
    """The object key and operation of a request tail (`request_tail`), remembered."""
    (n_key,) = _U16.unpack_from(tail)
    at = 2
    key = bytes(tail[at : at + n_key])
    at += n_key
    (n_op,) = _U16.unpack_from(tail, at)
    at += 2
    op_bytes = bytes(tail[at : at + n_op])
    if len(key) != n_key or len(op_bytes) != n_op or at + n_op != len(tail):
        raise FrameError("request header is truncated or has trailing bytes")
    target = key, op_bytes.decode("utf-8")
    if len(tail) <= MAX_TARGET_BYTES:
        if len(_targets) >= MAX_TARGETS:  # many objects, or someone making up keys: start again
            _targets.clear()
        _targets[tail] = target
    return target


def encode_reply(r: Reply) -> bytes:
    return reply_header(r.request_id, r.status, r.repo_id)


def reply_header(request_id: int, status: int, repo_id: str = "") -> bytes:
    """A reply header (`encode_reply` without building a `Reply` first)."""
    if not repo_id:
        return _REPLY.pack(VERSION, Kind.REPLY, status, 0, 0, request_id, 0)
    repo = repo_id.encode("utf-8")
    if len(repo) > MAX_NAME:
        raise ValueError("repository ids are limited to 65535 bytes")
    return _REPLY.pack(VERSION, Kind.REPLY, status, 0, 0, request_id, len(repo)) + repo


def ok_reply_id(frame: bytes | memoryview, head: bytes = _OK_REPLY) -> int:
    """The request id of a reply that says ok and carries no repository id (the common case,
    checked with the least work); -1 for any other frame, which `decode_reply` then reads."""
    if len(frame) == _REPLY.size and frame[:4] == head and frame[16:] == b"\0\0":
        return int.from_bytes(frame[8:16], "little")
    return -1


def shared_reply_header(request_id: int) -> bytes:
    """The header of an ok reply whose body frame is a descriptor (`transport.rpc.shared`),
    sent only to callers that announced they take them."""
    return _REPLY.pack(VERSION, Kind.REPLY, Status.OK, SHARED, 0, request_id, 0)


def shared_reply_id(frame: bytes | memoryview) -> int:
    """As `ok_reply_id`, for a reply whose body is in shared memory."""
    return ok_reply_id(frame, _SHARED_REPLY)


def decode_reply(frame: bytes | memoryview) -> Reply:
    try:
        version, kind, status, _, _, request_id, n_repo = _REPLY.unpack_from(frame)
        ok = not status and not n_repo and version == VERSION and kind == Kind.REPLY
        if ok and len(frame) == _REPLY.size:  # the common case: ok, no repository id
            return Reply(request_id, _OK)
        _check_version(version)
        if kind != Kind.REPLY:
            raise FrameError(f"expected a reply, got frame kind {kind}")
        repo = bytes(frame[_REPLY.size :])
        if len(repo) != n_repo:
            raise FrameError("reply header is truncated or has trailing bytes")
        return Reply(request_id, Status(status), repo.decode("utf-8"))
    except (StructError, UnicodeDecodeError, ValueError) as e:
        if isinstance(e, FrameError):
            raise
        raise FrameError(f"malformed reply header: {e}") from None


def _check_version(version: int) -> None:
    if version != VERSION:
        raise FrameError(f"protocol version {version} is not supported (this is {VERSION})")
