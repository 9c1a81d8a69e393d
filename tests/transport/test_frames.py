"""Request and reply headers: round trips, and nothing but FrameError for bad frames."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.frames import FrameError, Reply, Request, Status

requests = st.builds(
    Request,
    request_id=st.integers(0, 2**64 - 1),
    key=st.binary(max_size=300),
    operation=st.text(max_size=100),
    timeout_ms=st.integers(0, 2**32 - 1),
    oneway=st.booleans(),
)
replies = st.builds(
    Reply,
    request_id=st.integers(0, 2**64 - 1),
    status=st.sampled_from(list(Status)),
    repo_id=st.text(max_size=100),
)


@given(requests)
def test_request_round_trip(r: Request) -> None:
    assert frames.decode_request(frames.encode_request(r)) == r


@given(replies)
def test_reply_round_trip(r: Reply) -> None:
    assert frames.decode_reply(frames.encode_reply(r)) == r


def test_layout_is_the_documented_one() -> None:
    """docs/PROTOCOL.md: version, kind, flags, reserved, timeout ms, request id, key, op."""
    head = frames.encode_request(Request(7, b"k1", "getData", 2500))
    assert head == (
        b"\x01\x01\x00\x00"
        + (2500).to_bytes(4, "little")
        + (7).to_bytes(8, "little")
        + b"\x02\x00k1"
        + b"\x07\x00getData"
    )
    reply = frames.encode_reply(Reply(7, Status.USER_EXCEPTION, "IDL:Miro/EDevIO:1.0"))
    assert reply[:16] == b"\x01\x03\x01\x00" + bytes(4) + (7).to_bytes(8, "little")
    assert reply[16:] == b"\x13\x00IDL:Miro/EDevIO:1.0"


@settings(max_examples=300)
@given(st.binary(max_size=64))
def test_random_bytes_are_frame_errors_or_frames(data: bytes) -> None:
    for decode in (frames.decode_request, frames.decode_reply):
        with contextlib.suppress(FrameError):
            decode(data)


@given(requests, replies)
def test_every_truncation_and_extension_is_refused(r: Request, p: Reply) -> None:
    for encoded, decode in (
        (frames.encode_request(r), frames.decode_request),
        (frames.encode_reply(p), frames.decode_reply),
    ):
        for n in range(len(encoded)):
            with pytest.raises(FrameError):
                decode(encoded[:n])
        with pytest.raises(FrameError):
            decode(encoded + b"x")


def test_other_versions_and_kinds_are_refused() -> None:
    good = frames.encode_request(Request(1, b"k", "op"))
    with pytest.raises(FrameError, match="version 2"):
        frames.decode_request(b"\x02" + good[1:])
    with pytest.raises(FrameError, match="expected a request"):
        frames.decode_request(frames.encode_reply(Reply(1, Status.OK)))
    with pytest.raises(FrameError, match="expected a reply"):
        frames.decode_reply(good)
    with pytest.raises(FrameError):
        frames.decode_reply(b"\x01\x03\x07" + frames.encode_reply(Reply(1, Status.OK))[3:])
    with pytest.raises(FrameError):  # an operation name that is not UTF-8
        frames.decode_request(good[:-3] + b"\x01\x00\xff")


def test_oversized_names_are_refused_when_encoding() -> None:
    with pytest.raises(ValueError):
        frames.encode_request(Request(1, b"k" * 70000, "op"))
    with pytest.raises(ValueError):
        frames.encode_reply(Reply(1, Status.OK, "x" * 70000))
