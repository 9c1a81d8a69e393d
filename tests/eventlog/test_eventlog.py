"""Event logs end to end: real processes on loopback record into MCAP files, and replay them.

A supplier process pushes ExampleEvents with uneven gaps into a channel hosted by `miro naming`;
`miro log record` writes them; `miro log play` replays the file into a consumer process, which
must see what a live consumer sees: same domain, type, payloads, sequence numbers and stamps,
in order, paced as recorded.
"""

from __future__ import annotations

import contextlib
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import Miro
import pytest
from eventlog_helpers import miro, proc, read_events, start_recorder, stop, supply
from loopback import NamingProcess, eventually, run_miro, service_env
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader, make_reader
from miro_cli import REPO, run_miro_idl

from miro_gen.eventlog.writer import LogWriter
from miro_gen.transport.events.frames import RawEvent


@pytest.fixture(scope="module")
def naming() -> Iterator[str]:
    process = NamingProcess(options=("--channel", "EventChannel"))
    yield process.endpoint
    process.stop()


def event(n: int) -> Miro.ExampleEventIDL:
    return Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), -float(n)))


@pytest.fixture(scope="module")
def recorded(naming: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A log of 60 events with gaps of 10, 30 and 5 ms, finished by Ctrl-C."""
    path = tmp_path_factory.mktemp("log") / "run.mcap"
    rec = start_recorder(naming, path)
    supply(naming, 60, 10, 30, 5)
    _, err = stop(rec, signal.SIGINT)
    assert rec.returncode == 0, err
    assert f"{path}: 60 events in" in err
    return path


def test_ctrl_c_finishes_a_file_foxglove_and_mcap_can_read(recorded: Path) -> None:
    with open(recorded, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 60
        assert summary.chunk_indexes  # chunked and indexed
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        [channel] = summary.channels.values()
        assert channel.topic == "robot1/ExampleEvent"
        assert channel.message_encoding == "cdr"
        schema = summary.schemas[channel.schema_id]
        assert schema.name == "Miro::ExampleEventIDL"
        assert schema.encoding == "omgidl"
        assert schema.data.decode() == Miro.ExampleEventIDL._data_schema
        messages = [m for _, _, m in reader.iter_messages()]
    assert [Miro.ExampleEventIDL.deserialize(m.data) for m in messages] == [
        event(n) for n in range(60)
    ]
    seqs = [m.sequence for m in messages]
    assert seqs == list(range(seqs[0], seqs[0] + 60))
    # Source stamps (1 ms before the push) are the publish times; log times are receive times,
    # so each comes after its publish time, and in the order received.
    assert all(m.publish_time < m.log_time for m in messages)
    assert [m.log_time for m in messages] == sorted(m.log_time for m in messages)


def replay_once(naming: str, recorded: Path) -> tuple[list[dict[str, Any]], float]:
    """Replay `recorded` at 1x into a consumer process; what it received, and how many
    seconds the player ran."""
    printer = proc("event_printer.py", "--naming", naming, "-MNC", "gui", "EventChannel")
    assert printer.stdout is not None
    assert printer.stdout.readline().strip() == "READY"
    started = time.monotonic()
    player = run_miro("log", "play", str(recorded), "--naming", naming, "-MNC", "robot1")
    took = time.monotonic() - started
    out, _ = stop(printer, signal.SIGTERM)
    assert player.returncode == 0, player.stderr
    assert "replayed 60 events" in player.stderr
    return read_events(out), took


def test_a_replay_looks_live_to_a_consumer_process(naming: str, recorded: Path) -> None:
    with open(recorded, "rb") as f:
        logged = [m for _, _, m in make_reader(f).iter_messages()]
    got, took = replay_once(naming, recorded)
    assert len(got) == 60
    assert [e["payload"] for e in got] == [repr(event(n)) for n in range(60)]
    assert {(e["domain"], e["type"]) for e in got} == {("robot1", "ExampleEvent")}
    assert [e["seq"] for e in got] == [m.sequence for m in logged]
    stamps = zip(got, logged, strict=True)
    assert all(abs(int(e["stamp"]) - m.publish_time) < 1000 for e, m in stamps)
    # Paced at 1x, not dumped: the player ran at least as long as the log spans (a lower
    # bound, which a load can only lengthen), and the consumer got the events in logged order
    # (the seq check above). How closely arrivals keep the recorded spacing is a timing
    # figure: bench/bench_record.py prints it.
    assert took >= (logged[-1].log_time - logged[0].log_time) / 1e9
    received = [int(e["received"]) for e in got]
    assert received == sorted(received)


def readable(path: Path) -> list[Any]:
    """The messages of a log being written, as far as they can be read now."""
    messages: list[Any] = []
    with open(path, "rb") as f, contextlib.suppress(Exception):
        for _, _, m in NonSeekingReader(f).iter_messages(log_time_order=False):
            messages.append(m)
    return messages


def test_a_killed_recorder_leaves_a_readable_file(naming: str, tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    rec = start_recorder(naming, path, "robot2/ExampleEvent")
    supply(naming, 40, 10, context="robot2")
    # A chunk is closed once it is a second old: wait until the file holds all 40.
    eventually(lambda: len(readable(path)) == 40, 30)
    stop(rec, signal.SIGKILL)
    messages = []
    # The mcap library reads it up to the cut, then says so.
    with open(path, "rb") as f, pytest.raises(EndOfFile):
        for _, _, m in NonSeekingReader(f).iter_messages(log_time_order=False):
            messages.append(m)
    assert [Miro.ExampleEventIDL.deserialize(m.data) for m in messages] == [
        event(n) for n in range(40)
    ]
    info = run_miro("log", "info", str(path))
    assert info.returncode == 0, info.stderr
    assert "events:    40" in info.stdout
    assert "robot2/ExampleEvent" in info.stdout
    assert "unfinished" in info.stderr


def test_a_recording_without_a_file_name_is_named_after_its_context_and_time(
    naming: str, tmp_path: Path
) -> None:
    """As rosbag2 and Miro's LogNotify: `<context>_<date>_<time>.mcap` in $MIRO_LOG, said."""
    logs = tmp_path / "logs"
    logs.mkdir()
    rec = miro(
        "log", "record", "--naming", naming, "-MNC", "robot7", "robot3/ExampleEvent",
        env=service_env(MIRO_LOG=str(logs)),
    )  # fmt: skip
    assert rec.stderr is not None
    line = rec.stderr.readline()
    (path,) = logs.iterdir()
    assert re.fullmatch(r"robot7_\d{4}-\d\d-\d\d_\d\d-\d\d-\d\d\.mcap", path.name), path.name
    assert line == f"recording robot3/ExampleEvent from EventChannel into {path}\n"
    supply(naming, 5, 10, context="robot3")
    _, err = stop(rec, signal.SIGINT)
    assert rec.returncode == 0, err
    assert f"{path}: 5 events in" in err
    assert len(readable(path)) == 5


def test_count_and_duration_end_a_recording_by_themselves(naming: str, tmp_path: Path) -> None:
    """`--count N` keeps exactly the first N events and finishes the file; `--duration S`
    finishes it after S seconds, events or none (rosbag's --duration, rostopic's -n)."""
    counted = tmp_path / "counted.mcap"
    rec = start_recorder(naming, counted, "robot4/ExampleEvent", "--count", "7")
    supply(naming, 20, 5, context="robot4")
    _, err = rec.communicate(timeout=20)
    assert rec.returncode == 0, err
    assert f"{counted}: 7 events in" in err
    with open(counted, "rb") as f:
        messages = [m for _, _, m in make_reader(f).iter_messages()]  # finished: indexed
    assert [Miro.ExampleEventIDL.deserialize(m.data) for m in messages] == [
        event(n) for n in range(7)
    ]
    timed = tmp_path / "timed.mcap"
    rec = start_recorder(naming, timed, "robot5/ExampleEvent", "--duration", "0.3")
    _, err = rec.communicate(timeout=20)
    assert rec.returncode == 0, err
    assert f"{timed}: 0 events in" in err
    with open(timed, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 0


def test_damaged_files_are_errors_not_tracebacks(recorded: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    data = recorded.read_bytes()
    with open(recorded, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[0]
    cut.write_bytes(data[: chunk.chunk_start_offset + chunk.chunk_length // 2])
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    text = tmp_path / "notes.txt"
    text.write_text("not a log\n")
    for path, why in (
        (cut, "truncated inside a record"),
        (garbage, "after byte 8"),
        (text, "not an MCAP file"),
        (tmp_path / "missing.mcap", "cannot open"),
    ):
        for command in ("info", "echo", "play"):
            result = run_miro("log", command, str(path))
            assert result.returncode == 1, (command, path, result.stderr)
            assert f"{path}: error: " in result.stderr
            assert why in result.stderr, result.stderr
            assert "Traceback" not in result.stderr


def test_echo_prints_decoded_events_of_chosen_topics(recorded: Path) -> None:
    result = run_miro("log", "echo", str(recorded), "robot1/ExampleEvent", "-n", "3")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 3
    assert " robot1/ExampleEvent #" in lines[1] and lines[1].endswith(repr(event(1)))
    none = run_miro("log", "echo", str(recorded), "robot9/*")
    assert none.returncode == 1 and none.stdout == ""
    assert "no topic matches robot9/*; the log's topics: robot1/ExampleEvent" in none.stderr


def test_info_lists_topics_types_counts_and_rates(recorded: Path) -> None:
    result = run_miro("log", "info", str(recorded))
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "(finished)" in out and "events:    60" in out and "duration:" in out
    assert "robot1/ExampleEvent  Miro::ExampleEventIDL" in out and " Hz" in out


def test_usage_errors(tmp_path: Path) -> None:
    existing = tmp_path / "x.mcap"
    existing.write_bytes(b"")
    for args, message in (
        (("log", "record", "-o", str(existing)), "exists (use --force"),
        (("log", "record", "-o", "y.mcap", "a/"), "is not DOMAIN/TYPE"),
        (("log", "play", "x.mcap", "--rate", "0"), "--rate must be more than 0"),
        (("log", "record", "-o", "y.mcap", "--naming"), "--naming needs a value"),
        (("log", "record", "-o", "y.mcap", "--count", "0"), "'0' is not a positive whole"),
        (("log", "record", "-o", "y.mcap", "--duration", "soon"), "'soon' is not a positive"),
        (("log", "record", "-o", "y.mcap", "--ros2", "-n", "3"), "--count is for Miro"),
    ):
        result = run_miro(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert message in result.stderr and "usage:" in result.stderr


def test_echo_decodes_types_not_generated_here_from_the_log(tmp_path: Path) -> None:
    """A log from another project: its types are compiled from the schemas in the file."""
    compiled = run_miro_idl("-o", str(tmp_path / "gen"), str(REPO / "tests/foxglove/FoxTest.idl"))
    assert compiled.returncode == 0, compiled.stderr
    sys.path.insert(0, str(tmp_path / "gen"))
    try:
        import FoxTest

        scan = FoxTest.Scan(id=7, name="far", last_reading=FoxTest.Reading(label="x"))
        h = FoxTest.Scan._type_hash
        path = tmp_path / "foreign.mcap"
        writer = LogWriter(str(path))
        writer.write([RawEvent("r", "Scan", h, 1, 0, 5, 5, scan.serialize())], 10)
        writer.finish()
    finally:
        sys.path.remove(str(tmp_path / "gen"))
        for name in [m for m in sys.modules if m.split(".")[0] == "FoxTest"]:
            del sys.modules[name]
    result = run_miro("log", "echo", str(path))  # FoxTest is not on this one's path
    assert result.returncode == 0, result.stderr
    assert result.stdout.rstrip().endswith(repr(scan)), result.stdout


def test_an_empty_log_and_a_reader_that_goes_away(recorded: Path, tmp_path: Path) -> None:
    empty = tmp_path / "empty.mcap"
    LogWriter(str(empty)).finish()
    info = run_miro("log", "info", str(empty))
    assert info.returncode == 0 and "(finished)" in info.stdout and "events:    0" in info.stdout
    assert info.stderr == ""
    # `| head -1`: the rest of the output has nowhere to go, and that is not an error.
    piped = subprocess.run(
        f"{sys.executable} -m miro_gen.cli.main log echo {recorded} | head -1",
        shell=True,
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=30,
    )
    assert piped.stdout.count("\n") == 1 and piped.stderr == ""
