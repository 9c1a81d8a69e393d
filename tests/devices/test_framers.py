"""Framers cut a device's byte stream into messages, however the reads split it."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from miro_gen.devices import DelimitedFramer, FixedLengthFramer, LengthPrefixedFramer, LineFramer
from miro_gen.devices.framers import Framer


def feed_in_pieces(framer: Framer, data: bytes, cuts: list[int]) -> list[bytes]:
    out: list[bytes] = []
    at = 0
    for cut in sorted(c % (len(data) + 1) for c in cuts):
        out += framer.feed(data[at:cut]) if cut >= at else []
        at = max(at, cut)
    return out + framer.feed(data[at:])


lines = st.lists(
    st.binary(min_size=1, max_size=40).map(lambda b: b.replace(b"\n", b"x")), max_size=20
)


@given(lines, st.lists(st.integers(min_value=0, max_value=10_000), max_size=30))
def test_lines_come_out_whole_whatever_the_reads(messages: list[bytes], cuts: list[int]) -> None:
    messages = [m.rstrip(b"\r") for m in messages if m.rstrip(b"\r")]
    data = b"".join(m + b"\r\n" for m in messages)
    assert feed_in_pieces(LineFramer(), data, cuts) == messages


def test_a_line_over_the_limit_is_dropped_and_counted() -> None:
    framer = LineFramer(max_length=10)
    assert framer.feed(b"short\n" + b"x" * 25 + b"\nok\n") == [b"short", b"ok"]
    assert framer.discarded == 25
    assert framer.feed(b"y" * 30) == []  # no terminator in sight: dropped, not hoarded
    assert framer.discarded == 55


sentences = st.lists(
    st.text(alphabet="ABCDEFGHIJ0123456789,.*", min_size=1, max_size=60).map(
        lambda s: b"$" + s.encode() + b"\r\n"
    ),
    max_size=15,
)


@given(sentences, st.binary(max_size=20), st.lists(st.integers(0, 10_000), max_size=30))
def test_delimited_messages_survive_noise_between_them(
    messages: list[bytes], noise: bytes, cuts: list[int]
) -> None:
    noise = noise.replace(b"$", b"")
    data = b"".join(noise + m for m in messages)
    framer = DelimitedFramer(b"$", b"\r\n")
    assert feed_in_pieces(framer, data, cuts) == messages


def test_a_restarted_message_abandons_the_partial_one() -> None:
    framer = DelimitedFramer(b"$", b"\r\n")
    assert framer.feed(b"$GPGGA,12") == []
    assert framer.feed(b"$GPRMC,1*00\r\n") == [b"$GPRMC,1*00\r\n"]
    assert framer.discarded == len(b"$GPGGA,12")


@given(st.binary(max_size=200), st.lists(st.integers(0, 1000), max_size=20))
def test_fixed_length(data: bytes, cuts: list[int]) -> None:
    n = len(data) // 8 * 8
    expected = [data[i : i + 8] for i in range(0, n, 8)]
    assert feed_in_pieces(FixedLengthFramer(8), data, cuts) == expected


@given(
    st.lists(st.binary(max_size=300), max_size=10),
    st.lists(st.integers(0, 10_000), max_size=30),
)
def test_length_prefixed_with_sync(payloads: list[bytes], cuts: list[int]) -> None:
    messages = [b"\xaa\x55" + len(p).to_bytes(2, "little") + p for p in payloads]
    framer = LengthPrefixedFramer(2, offset=2, byteorder="little", sync=b"\xaa\x55")
    assert feed_in_pieces(framer, b"junk" + b"".join(messages), cuts) == messages


def test_a_corrupt_length_resynchronises() -> None:
    framer = LengthPrefixedFramer(1, offset=1, sync=b"\x02", max_length=16)
    good = b"\x02\x03abc"
    assert framer.feed(b"\x02\xff" + good) == [good]  # 0xff is over the limit: resync
    assert framer.discarded == 2


def test_framer_arguments_are_checked() -> None:
    with pytest.raises(ValueError):
        LineFramer(b"")
    with pytest.raises(ValueError):
        LengthPrefixedFramer(3)
    with pytest.raises(ValueError):
        DelimitedFramer(b"", b"\n")
