"""The payloads of event batch frames (what the Foxglove bridge forwards): the same as the
events parse_batch reads, for payloads of one size (one Struct call) and of many, and nothing
but FrameError for frames cut short, extended or made up."""

from __future__ import annotations

import contextlib

from hypothesis import given, settings
from hypothesis import strategies as st

from miro_gen.transport.events.frames import (
    FrameError,
    batch_payloads,
    pack_batch,
    parse_batch,
)

TYPE_HASH = "ab" * 32
payload_lists = st.one_of(
    # one size: the one-call path, lengths checked
    st.integers(0, 40).flatmap(lambda n: st.lists(st.binary(min_size=n, max_size=n), max_size=120)),
    st.lists(st.binary(max_size=40), max_size=30),  # sizes mixed: a step each
)


def frame_of(payloads: list[bytes]) -> bytes:
    return pack_batch(7, TYPE_HASH, [(i, i, -i, p) for i, p in enumerate(payloads)])


@settings(max_examples=300)
@given(payload_lists)
def test_payloads_are_the_events_payloads(payloads: list[bytes]) -> None:
    body = frame_of(payloads)
    for form in (body, memoryview(body)):  # bytes (small frames), a view (large ones)
        raw_hash, got = batch_payloads(form)
        assert raw_hash.hex() == TYPE_HASH
        assert list(got) == payloads == [e.data for e in parse_batch("d", "T", body)]
        assert all(type(p) is bytes for p in got)  # what the Foxglove SDK's log takes


def test_a_large_payload_alone() -> None:
    image = bytes(range(256)) * 4096  # 1 MB
    _, got = batch_payloads(memoryview(frame_of([image])))
    assert list(got) == [image]


@settings(max_examples=300)
@given(payload_lists, st.data())
def test_every_cut_and_extension_is_refused(payloads: list[bytes], data: st.DataObject) -> None:
    body = frame_of(payloads)
    cut = data.draw(st.integers(0, max(0, len(body) - 1)))
    extra = data.draw(st.binary(min_size=1, max_size=60))
    for bad in (body[:cut], body + extra):
        try:
            _, got = batch_payloads(bad)
        except FrameError:
            continue
        # what parses must be what the reference parser reads
        assert list(got) == [e.data for e in parse_batch("d", "T", bad)]


def test_lengths_that_differ_but_fill_the_frame_evenly() -> None:
    """Two events of 10 and 30 bytes fill the frame as two of 20 would: read one by one."""
    payloads = [b"a" * 10, b"b" * 30]
    assert list(batch_payloads(frame_of(payloads))[1]) == payloads


@settings(max_examples=300)
@given(st.binary(max_size=200))
def test_made_up_frames_are_frame_errors_or_frames(body: bytes) -> None:
    with contextlib.suppress(FrameError):
        batch_payloads(b"\x01" + body)
