"""Logs that cannot lie or break (issue 21): damaged files are errors that name the chunk, never
wrong values; zstd bombs are capped; a log's schemas are compiled without directives and under
limits; the recorder refuses topics past MCAP's 65,535 channels and finishes a readable file.
Files are real MCAP files read back by our reader, the `miro log` tools and mcap's own reader."""

from __future__ import annotations

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

from miro_gen.compile import foreign
from miro_gen.eventlog import types
from miro_gen.eventlog.reader import LogError, LogReader
from miro_gen.eventlog.writer import MAX_CHANNELS, LogWriter
from miro_gen.transport.events.frames import RawEvent

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


# Started by a small Python process of its own, which reports its child's peak: a process's
# ru_maxrss counts the memory of the one it was forked from (the high-water mark of the image it
# replaced at exec), and this test process may be hundreds of MiB by then.
_MEASURE = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
sys.stderr.write(done.stderr)
print(done.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def peak_rss_mb(*args: str) -> tuple[int, float, str]:
    """Run `miro ARGS`; its exit status, peak resident memory (MiB) and stderr."""
    done = subprocess.run(
        [sys.executable, "-c", _MEASURE, sys.executable, "-m", "miro_gen.cli.main", *args],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=300,
    )
    status, kib = done.stdout.split()
    return int(status), int(kib) / 1024, done.stderr


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
    monkeypatch.setattr(foreign, "COMPILE_SECONDS", 0.01)
    why = types.types_from_schemas(["module Slow { struct S { long x; }; };"])
    assert why is not None and "took longer than" in why
    monkeypatch.setattr(foreign, "COMPILE_SECONDS", 60.0)
    monkeypatch.setattr(foreign, "COMPILE_MEMORY", 16 << 20)  # not even the compiler loads
    why = types.types_from_schemas(["module Small { struct S { long x; }; };"])
    assert why is not None and "ran out of its time or memory" in why
    monkeypatch.setattr(foreign, "COMPILE_MEMORY", 2 << 30)
    monkeypatch.setattr(foreign, "MAX_SCHEMA_BYTES", 100)
    why = types.types_from_schemas(
        [f"module Big{n} {{ struct S {{ long x; }}; }};" for n in range(9)]
    )
    assert why is not None and "larger than 100 bytes" in why
    why = types.types_from_schemas(["module Bad { struct S { long x } };"])
    assert why is not None and why.startswith("the schema does not compile here: schema.idl:1:")


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


# -- miro log info and damaged chunks (issue 33) ------------------------------------------------
def _damaged_copies(tmp_path: Path) -> tuple[Path, dict[str, Path], int]:
    """A good log and copies of it damaged in its third chunk (of six): a bit of its zstd data
    flipped, its record length changed, its first log time changed. The summary is intact."""
    good = tmp_path / "good.mcap"
    write_log(good)
    data = good.read_bytes()
    with open(good, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.chunk_indexes) == 6
    index = summary.chunk_indexes[2]
    at = index.chunk_start_offset
    copies = {}
    for name, offset, bit in (
        ("flipped", at + index.chunk_length - 20, 0x10),  # in its compressed data
        ("length", at + 1, 0x01),  # its record's length
        ("time", at + 9, 0x01),  # its header's first log time
    ):
        damaged = bytearray(data)
        damaged[offset] ^= bit
        copies[name] = tmp_path / f"{name}.mcap"
        copies[name].write_bytes(damaged)
    return good, copies, at


def test_info_check_reads_every_chunk(tmp_path: Path) -> None:
    """Before: `miro log info` called a file with a damaged chunk "finished" (it read the
    summary only). With --check, every chunk is read: each damaged one is an error line that
    names it, and the exit status is 1; a good file says what was checked."""
    good, copies, at = _damaged_copies(tmp_path)
    ok = run_miro("log", "info", "--check", str(good))
    assert ok.returncode == 0, ok.stderr
    assert ok.stderr == ""
    assert "(finished)" in ok.stdout
    assert "checked:   6 chunks, 300 events: readable, as the summary says" in ok.stdout
    for name, path in copies.items():
        r = run_miro("log", "info", "--check", str(path))
        assert r.returncode == 1, (name, r.stderr)
        assert "Traceback" not in r.stderr
        assert f"({'damaged'})" in r.stdout, r.stdout
        errors = r.stderr.splitlines()
        assert errors and all(ln.startswith(f"{path}: error: ") for ln in errors), r.stderr
        assert errors[0].startswith(f"{path}: error: chunk 3 (at byte {at}, log time "), r.stderr


def test_info_warns_when_a_cheap_check_finds_damage(tmp_path: Path) -> None:
    """Without --check, each chunk's header is compared with the index, and the data
    section's CRC (which our recorder writes) with its bytes: a damaged file is no longer
    "finished", with warning lines and a pointer to --check; the summary is still shown."""
    good, copies, at = _damaged_copies(tmp_path)
    ok = run_miro("log", "info", str(good))
    assert ok.returncode == 0 and ok.stderr == "", ok.stderr
    assert "(finished)" in ok.stdout
    for name, path in copies.items():
        r = run_miro("log", "info", str(path))
        assert r.returncode == 0, (name, r.stderr)
        assert "(finished, but its summary and chunks disagree)" in r.stdout, r.stdout
        assert "events:    300" in r.stdout
        lines = r.stderr.splitlines()
        warnings = [ln for ln in lines if ln.startswith(f"{path}: warning: ")]
        assert warnings and lines[-1] == f"{path}: note: 'miro log info --check' reads every chunk"
        assert len(warnings) == len(lines) - 1, r.stderr
        if name == "flipped":  # only the CRC can tell
            assert warnings == [
                f"{path}: warning: summary and chunks disagree: the data section's CRC does "
                "not match its bytes: some were changed after writing"
            ]
        else:
            assert warnings[0].startswith(
                f"{path}: warning: summary and chunks disagree: chunk 3 (at byte {at}, "
            ), r.stderr


def test_info_check_finds_a_chunk_the_index_leaves_out(tmp_path: Path) -> None:
    """A file whose summary (intact, its CRC right) leaves out its second chunk: the summary
    agrees with itself, --check finds the chunk it does not count."""
    path = tmp_path / "extra.mcap"
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1 << 20)
        w.start()
        sid = w.register_schema("S", "omgidl", b"struct S { long a; };")
        cid = w.register_channel("robot/S", "cdr", sid)
        finalize = w._Writer__finalize_chunk  # type: ignore[attr-defined]
        for t in (1, 2):
            w.add_message(cid, t, b"\0\1\0\0\1\0\0\0", t)
            finalize()
        w._Writer__chunk_indices.pop()  # type: ignore[attr-defined]
        stats = w._Writer__statistics  # type: ignore[attr-defined]
        stats.message_count -= 1
        stats.chunk_count -= 1
        stats.message_end_time = 1
        stats.channel_message_counts[cid] -= 1
        w.finish()
    quick = run_miro("log", "info", str(path))
    assert quick.returncode == 0 and quick.stderr == "", quick.stderr
    assert "events:    1" in quick.stdout
    r = run_miro("log", "info", "--check", str(path))
    assert r.returncode == 1, r.stderr
    assert r.stderr.splitlines() == [
        f"{path}: error: a chunk at byte {_chunk_offsets(path)[1]} (log time 2 to 2 ns) is not in "
        "the file's index: the summary does not count its events"
    ]


def _chunk_offsets(path: Path) -> list[int]:
    """Where the chunk records of the file's data section start (walked record by record)."""
    data = path.read_bytes()
    at, found = len(MAGIC), []
    while at < len(data):
        opcode, length = struct.unpack_from("<BQ", data, at)
        if opcode == 0x06:  # Chunk
            found.append(at)
        elif opcode == 0x0F:  # DataEnd
            break
        at += 9 + length
    return found
