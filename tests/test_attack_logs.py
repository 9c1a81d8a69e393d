"""Logs that cannot lie or break (issue 21): damaged files are errors that name the chunk, never
wrong values; zstd bombs are capped; a log's schemas are compiled without directives and under
limits; the recorder refuses topics past MCAP's 65,535 channels and finishes a readable file.
Files are real MCAP files read back by our reader, the `miro log` tools and mcap's own reader."""

from __future__ import annotations

import os
import random
import struct
import subprocess
import sys
from pathlib import Path

import Miro
import pytest
import zstandard
from loopback import run_miro, service_env
from mcap.reader import make_reader
from mcap.writer import Writer

from miro_gen.eventlog import types
from miro_gen.eventlog.reader import LogError, LogReader
from miro_gen.eventlog.writer import MAX_CHANNELS, LogWriter
from miro_gen.transport.event_frames import RawEvent

MAGIC = b"\x89MCAP0\r\n"


def write_log(path: Path, topics: int = 3, count: int = 300, chunks: int = 6) -> None:
    """A log of `count` ExampleEvents over `topics` topics, in about `chunks` chunks."""
    writer = LogWriter(str(path))
    type_hash = Miro.ExampleEventIDL._type_hash
    for n in range(count):
        e = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), -float(n)))
        raw = RawEvent(
            f"robot{n % topics}", "ExampleEvent", type_hash, 1, n, n * 1000, 0, e.serialize()
        )
        writer.write([raw], 1_700_000_000_000_000_000 + n * 1_000_000)
        if (n + 1) % (count // chunks) == 0:
            writer.flush()
    writer.finish()


def read_all(path: Path) -> list[tuple[str, int, int, int, bytes]]:
    with LogReader(str(path)) as log:
        return [
            (t.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
            for t, m in log.messages()
        ]


def test_bit_flips_are_errors_or_harmless_never_wrong_values(tmp_path: Path) -> None:
    """Before: 31 of 100 files with one bit flipped printed wrong values with exit 0 (chunk
    CRCs were not checked). Now every flip either leaves what is read unchanged or is an
    error; a flip inside a chunk is an error naming the chunk."""
    good = tmp_path / "good.mcap"
    write_log(good)
    expected = read_all(good)
    assert len(expected) == 300
    data = good.read_bytes()
    rng = random.Random(21)
    wrong, errors = [], 0
    flipped = tmp_path / "flipped.mcap"
    for _ in range(100):
        at = rng.randrange(len(MAGIC), len(data))
        damaged = bytearray(data)
        damaged[at] ^= 1 << rng.randrange(8)
        flipped.write_bytes(damaged)
        try:
            got = read_all(flipped)
        except LogError:
            errors += 1
            continue
        if got != expected:
            wrong.append(at)
    assert not wrong, f"flips at bytes {wrong} gave other values without an error"
    assert errors > 30

    with open(good, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    index = summary.chunk_indexes[2]
    damaged = bytearray(data)
    damaged[index.chunk_start_offset + index.chunk_length - 20] ^= 0x10  # in its zstd data
    flipped.write_bytes(damaged)
    echo = run_miro("log", "echo", str(flipped))
    assert echo.returncode == 1
    assert f"chunk 3 (at byte {index.chunk_start_offset}" in echo.stderr, echo.stderr
    assert "Traceback" not in echo.stderr


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def _string(text: str) -> bytes:
    return struct.pack("<I", len(text)) + text.encode()


def bomb_file(path: Path, claimed: int, real: int) -> None:
    """An unfinished MCAP file whose one zstd chunk decompresses to `real` zero bytes and
    says `claimed`."""
    compressor = zstandard.ZstdCompressor(level=1).compressobj()
    zeros = bytes(16 << 20)
    parts = [compressor.compress(zeros) for _ in range(real // len(zeros))]
    packed = b"".join([*parts, compressor.flush()])
    header = _record(0x01, _string("") + _string("bomb"))
    chunk = _record(
        0x06,
        struct.pack("<QQQI", 0, 0, claimed, 0)
        + _string("zstd")
        + struct.pack("<Q", len(packed))
        + packed,
    )
    path.write_bytes(MAGIC + header + chunk)


def peak_rss_mb(*args: str) -> tuple[int, float, str]:
    """Run `miro ARGS`; its exit status, peak resident memory (MiB) and stderr."""
    p = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )
    assert p.stderr is not None
    err = p.stderr.read()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    return p.returncode, usage.ru_maxrss / 1024, err


def test_a_zstd_bomb_is_refused_without_being_inflated(tmp_path: Path) -> None:
    """Before: 98 KB of zstd took 6.3 GB (the chunk's size was believed). Now a chunk may hold
    at most MAX_CHUNK_BYTES, and decompressing stops at the size it claims."""
    honest = tmp_path / "honest.mcap"  # says 1 GiB, the truth, and more than a chunk may be
    bomb_file(honest, 1 << 30, 1 << 30)
    assert honest.stat().st_size < 100_000
    liar = tmp_path / "liar.mcap"  # says 1 KB, decompresses to 1 GiB
    bomb_file(liar, 1000, 1 << 30)
    for path, why in (
        (honest, "more than the"),
        (liar, "decompresses to more than the 1000 bytes"),
    ):
        status, rss, err = peak_rss_mb("log", "echo", str(path))
        assert status == 1, err
        assert "chunk 1 (at byte" in err and why in err, err
        assert rss < 300, f"reading {path.name} took {rss:.0f} MiB"


def hostile_log(path: Path, schema: str) -> None:
    """A log with one event of a type nobody here has, whose schema is `schema`."""
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        sid = writer.register_schema("H::S", "omgidl", schema.encode())
        cid = writer.register_channel(
            "robot/S", "cdr", sid, {"domain": "robot", "type_name": "S", "type_hash": "ab" * 32}
        )
        writer.add_message(cid, 1, b"\x00\x01\x00\x00\x07\x00\x00\x00", 1, 0)
        writer.finish()


@pytest.mark.parametrize(
    "include", ['#include "/etc/passwd"', '#include "/dev/zero"', "/**/ #include </dev/stdin>"]
)
def test_a_hostile_schema_is_not_preprocessed(tmp_path: Path, include: str) -> None:
    """Before: a schema's `#include "/etc/passwd"` was read, and a 2 KB schema hung `miro log
    echo`. Now a schema with directives is not compiled at all: the events are shown undecoded
    and the tool goes on."""
    path = tmp_path / "hostile.mcap"
    hostile_log(path, include + "\nmodule H { struct S { long x; }; };\n")
    echo = subprocess.run(  # (the timeout: it must not hang)
        [sys.executable, "-m", "miro_gen.cli.main", "log", "echo", str(path)],
        capture_output=True,
        text=True,
        env=service_env(),
        stdin=subprocess.DEVNULL,
        timeout=120,
    )
    assert echo.returncode == 0, echo.stderr
    assert "preprocessor directives" in echo.stderr
    assert "no generated type here has type hash abababababab" in echo.stdout
    said = echo.stdout + echo.stderr  # before: "/etc/passwd:1:1: error: unexpected 'root'"
    assert "passwd:" not in said and "'root'" not in said


def test_compiling_a_schema_is_stopped_past_its_limits(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(types, "COMPILE_SECONDS", 0.01)
    why = types.types_from_schemas(["module Slow { struct S { long x; }; };"])
    assert why is not None and "took longer than" in why
    monkeypatch.setattr(types, "COMPILE_SECONDS", 60.0)
    monkeypatch.setattr(types, "COMPILE_MEMORY", 16 << 20)  # not even Python starts in that
    why = types.types_from_schemas(["module Small { struct S { long x; }; };"])
    assert why is not None and "do not compile" in why
    monkeypatch.setattr(types, "MAX_SCHEMA_BYTES", 100)
    why = types.types_from_schemas(
        [f"module Big{n} {{ struct S {{ long x; }}; }};" for n in range(9)]
    )
    assert why is not None and "larger than 100 bytes" in why


def test_topics_past_the_channel_limit_are_refused_and_the_rest_recorded(
    tmp_path: Path,
) -> None:
    """Before: a recording with more than 65,535 topics crashed the recorder (MCAP's channel
    ids are 16 bits) and corrupted the file from there on. Now the topics past the limit are
    refused, counted, and everything else recorded into a file that reads back."""
    path = tmp_path / "many.mcap"
    writer = LogWriter(str(path))
    type_hash = Miro.ExampleEventIDL._type_hash
    payload = Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, 2.0)).serialize()
    extra = 40
    for n in range(MAX_CHANNELS + extra):
        writer.write([RawEvent(f"d{n}", "ExampleEvent", type_hash, 1, 0, 0, 0, payload)], n + 1)
    writer.write([RawEvent("d0", "ExampleEvent", type_hash, 1, 1, -5, 0, payload)], 10**6)
    writer.finish()
    assert writer.refused == extra and writer.messages == MAX_CHANNELS + 1
    with LogReader(str(path)) as log:
        assert len(log.topics()) == MAX_CHANNELS
        assert sum(1 for _ in log.messages()) == MAX_CHANNELS + 1
    with open(path, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == MAX_CHANNELS + 1
