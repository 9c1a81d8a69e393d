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
from typing import Final, NamedTuple

from miro_gen.runtime.rpc import ReplyStatus as Status

VERSION: Final = 1
MAX_NAME: Final = 0xFFFF  # bytes of an object key, operation name or repository id


class Kind(enum.IntEnum):
    REQUEST = 1  # a reply is expected
    ONEWAY = 2  # no reply
    REPLY = 3


class FrameError(ValueError):
    """A frame that is not a valid frame of this protocol version."""


# version, kind, flags, reserved, timeout ms, request id | key length (then key, op length, op)
_REQUEST: Final = Struct("<BBBBIQH")
# version, kind, status, reserved, reserved, request id | repository id length (then the id)
_REPLY: Final = Struct("<BBBBIQH")
_U16: Final = Struct("<H")


class Request(NamedTuple):
    request_id: int
    key: bytes
    operation: str
    timeout_ms: int = 0  # how long the caller waits (0: no limit); late requests are skipped
    oneway: bool = False


class Reply(NamedTuple):
    request_id: int
    status: Status
    repo_id: str = ""


def encode_request(r: Request) -> bytes:
    op = r.operation.encode("utf-8")
    if len(r.key) > MAX_NAME or len(op) > MAX_NAME:
        raise ValueError("object key and operation name are limited to 65535 bytes")
    kind = Kind.ONEWAY if r.oneway else Kind.REQUEST
    head = _REQUEST.pack(VERSION, kind, 0, 0, r.timeout_ms, r.request_id, len(r.key))
    return head + r.key + _U16.pack(len(op)) + op


def decode_request(frame: bytes) -> Request:
    try:
        version, kind, _, _, timeout_ms, request_id, n_key = _REQUEST.unpack_from(frame)
        _check_version(version)
        if kind not in (Kind.REQUEST, Kind.ONEWAY):
            raise FrameError(f"expected a request, got frame kind {kind}")
        at = _REQUEST.size
        key = bytes(frame[at : at + n_key])
        at += n_key
        (n_op,) = _U16.unpack_from(frame, at)
        at += 2
        op_bytes = bytes(frame[at : at + n_op])
        if len(key) != n_key or len(op_bytes) != n_op or at + n_op != len(frame):
            raise FrameError("request header is truncated or has trailing bytes")
        operation = op_bytes.decode("utf-8")
    except (StructError, UnicodeDecodeError) as e:
        raise FrameError(f"malformed request header: {e}") from None
    return Request(request_id, key, operation, timeout_ms, kind == Kind.ONEWAY)


def encode_reply(r: Reply) -> bytes:
    repo = r.repo_id.encode("utf-8")
    if len(repo) > MAX_NAME:
        raise ValueError("repository ids are limited to 65535 bytes")
    return _REPLY.pack(VERSION, Kind.REPLY, r.status, 0, 0, r.request_id, len(repo)) + repo


def decode_reply(frame: bytes) -> Reply:
    try:
        version, kind, status, _, _, request_id, n_repo = _REPLY.unpack_from(frame)
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
