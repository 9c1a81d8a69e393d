"""`miro log play` of several robots' logs: each robot's events into that robot's channel (the
player hosts and binds ROBOT/EventChannel), or all into one (--unified-channel), or into the
channels that exist (--shared-channels); consumer processes in each robot's naming context
receive them. And the terminal's seek and speed keys; and `miro log cut` and `miro log merge`
on the command line.
"""

from __future__ import annotations

import re
import signal
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from eventlog_helpers import T0, miro, proc, read_events, stop, write_log
from loopback import NamingProcess, eventually, run_miro
from mcap.reader import make_reader
from qt_procs import ServiceProcess
from test_log_terminal import Terminal

N = 20  # events of each robot, 10 ms apart, robotB 5 ms after robotA


@pytest.fixture
def logs(tmp_path: Path) -> tuple[Path, Path]:
    a = write_log(tmp_path / "robotA.mcap", [("robotA", n, 10 * n) for n in range(N)])
    b = write_log(tmp_path / "robotB.mcap", [("robotB", n, 10 * n + 5) for n in range(N)])
    return a, b


@pytest.fixture
def naming() -> Iterator[str]:
    process = NamingProcess()  # no channel at the root: each robot's is the player's
    yield process.endpoint
    process.stop()


def printer(naming: str, context: str) -> ServiceProcess:
    """A consumer process in naming context `context`, of its `EventChannel` (which it waits
    for: the player binds it), its lines read as they come."""
    return ServiceProcess(
        "tests/procs/event_printer.py", "--naming", naming, "-MNC", context, "EventChannel"
    )


def ready(p: subprocess.Popen[str]) -> None:
    assert p.stdout is not None and p.stdout.readline().strip() == "READY"


def play(naming: str, *args: str) -> subprocess.CompletedProcess[str]:
    done = run_miro("log", "play", *args, "--naming", naming, "--wait-subscribed", timeout=120)
    assert done.returncode == 0, done.stderr
    return done


def received(p: ServiceProcess, count: int) -> list[dict[str, Any]]:
    """The events the consumer printed, once it has printed `count` (then it is stopped)."""
    try:
        eventually(lambda: len(read_events("\n".join(p.lines))) >= count, 30)
    finally:
        p.stop()
    return read_events("\n".join(p.lines))


def test_each_robot_s_events_go_into_its_own_channel(naming: str, logs: tuple[Path, Path]) -> None:
    consumers = {robot: printer(naming, robot) for robot in ("robotA", "robotB")}
    try:
        done = play(naming, *map(str, logs))  # the consumers find the channels it binds
    finally:
        got = {robot: received(p, N) for robot, p in consumers.items()}
    assert "into robotA/EventChannel, robotB/EventChannel" in done.stderr
    assert f"replayed {2 * N} events" in done.stderr
    for robot, events in got.items():
        assert [(e["domain"], e["seq"]) for e in events] == [(robot, n) for n in range(N)]
        stamps = [T0 + (10 * n + (5 if robot == "robotB" else 0) - 1) * 1_000_000 for n in range(N)]
        assert all(abs(e["stamp"] - s) < 1000 for e, s in zip(events, stamps, strict=True))


def test_one_channel_for_all_the_robots(naming: str, logs: tuple[Path, Path]) -> None:
    consumer = printer(naming, "robotB")
    try:
        done = play(naming, *map(str, logs), "--unified-channel")
    finally:
        events = received(consumer, 2 * N)
    assert "into robotA/EventChannel" in done.stderr  # one channel, bound for both
    merged = [(e["domain"], e["seq"]) for e in events]
    assert merged == [(robot, n) for n in range(N) for robot in ("robotA", "robotB")]


def test_shared_channels_are_only_those_that_exist(naming: str, logs: tuple[Path, Path]) -> None:
    host = proc("channel_host.py", "--naming", naming, "-MNC", "robotA", "EventChannel")
    consumer = printer(naming, "robotA")
    try:
        ready(host)
        done = play(naming, *map(str, logs), "--shared-channels")
    finally:
        events = received(consumer, N)
        stop(host, signal.SIGTERM)
    assert "robotB: no channel robotB/EventChannel" in done.stderr
    assert [(e["domain"], e["seq"]) for e in events] == [("robotA", n) for n in range(N)]
    assert f"replayed {2 * N} events" in done.stderr  # robotB's were played into nothing


def test_the_terminal_s_seek_and_speed_keys(naming: str, tmp_path: Path) -> None:
    log = write_log(tmp_path / "ten.mcap", [("robot1", n, 250 * n) for n in range(41)])
    consumer = printer(naming, "robot1")
    term = Terminal("log", "play", str(log), "--naming", naming, "--wait-subscribed")
    try:
        term.read_until(lambda screen: "events  x1" in screen)
        term.key("0")  # back to the start, paused
        term.read_until(lambda screen: re.search(r"0\.00/10\.00 s  \d+ events  x1 paused", screen))
        sent = int(re.findall(r"0\.00/10\.00 s  (\d+) events  x1 paused", term.screen)[-1])
        term.key("]")  # a 20th of the log on: 0.5 s
        term.read_until(lambda screen: f"0.50/10.00 s  {sent} events" in screen)
        term.key("s")  # the event at 0.5 s
        term.read_until(lambda screen: f"0.50/10.00 s  {sent + 1} events" in screen)
        term.key("\x1b[1;2D")  # shift+left: back to the start
        term.read_until(lambda screen: f"0.00/10.00 s  {sent + 1} events" in screen)
        term.key("\x1b[C")  # right: the next event, the first
        term.read_until(lambda screen: f"0.00/10.00 s  {sent + 2} events" in screen)
        term.key("+")
        term.key("+")
        term.read_until(lambda screen: "x4 paused" in screen)
        term.key("-")
        term.read_until(lambda screen: "x2 paused" in screen)
        term.key("q")
        term.read_until(lambda screen: "replayed " in screen)
        assert term.close() == 0
    finally:
        if term.proc.poll() is None:
            term.proc.kill()
        events = received(consumer, sent + 2)
    seqs = [e["seq"] for e in events]
    assert seqs[sent:] == [2, 0], seqs


def test_waiting_for_consumers_says_which_topics_have_none_and_stops_on_sigterm(
    naming: str, tmp_path: Path
) -> None:
    """Before: `--wait-subscribed` said "waiting for a consumer of every topic" and nothing
    more, so a replay left waiting by a consumer of some topics only (or one that went away)
    looked hung; and SIGTERM while it waited started the replay before it stopped. Now it
    names the topics without a consumer, again as that changes, and SIGTERM ends it with
    nothing played."""
    a = write_log(tmp_path / "a.mcap", [("robot1", n, 10 * n) for n in range(N)])
    b = write_log(
        tmp_path / "b.mcap", [("robot1", n, 10 * n + 5) for n in range(N)], type_name="Other"
    )
    player = miro(
        "log", "play", str(a), str(b), "--naming", naming, "--wait", "0", "--wait-subscribed"
    )
    said: list[str] = []
    assert player.stderr is not None
    reader = threading.Thread(target=lambda: said.extend(player.stderr), daemon=True)  # type: ignore[arg-type]
    reader.start()
    consumer: ServiceProcess | None = None
    try:
        # The consumer comes once the player waits (else, started with it, it could subscribe
        # between the player's binding its channel and its first look, on a loaded machine).
        eventually(lambda: any("waiting for a consumer of" in line for line in said), 60)
        consumer = ServiceProcess(
            "tests/procs/event_printer.py",
            "--naming",
            naming,
            "-MNC",
            "robot1",
            "EventChannel",
            "robot1/ExampleEvent",
        )
        consumer.wait_line("READY", 60)
        eventually(lambda: any(line.endswith("consumer of robot1/Other\n") for line in said), 60)
        player.send_signal(signal.SIGTERM)
        player.wait(60)
        reader.join(10)
    finally:
        if player.poll() is None:
            player.kill()
        if consumer is not None:
            consumer.stop()
    waiting = [line.rstrip() for line in said if "waiting for a consumer of" in line]
    assert "robot1/ExampleEvent" in waiting[0] and "robot1/Other" in waiting[0], said
    assert waiting[-1].endswith("waiting for a consumer of robot1/Other"), said
    assert any("replayed 0 events" in line for line in said), said
    assert consumer is not None and read_events("\n".join(consumer.lines)) == []


# ---- cut and merge -----------------------------------------------------------------------------


def topics_and_seqs(path: Path) -> list[tuple[str, int]]:
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary() is not None
        return [(ch.topic, m.sequence) for _, ch, m in reader.iter_messages()]


def test_cut_and_merge_on_the_command_line(logs: tuple[Path, Path], tmp_path: Path) -> None:
    merged = tmp_path / "merged.mcap"
    done = run_miro("log", "merge", *map(str, logs), "-o", str(merged))
    assert done.returncode == 0, done.stderr
    assert f"{merged}: {2 * N} events" in done.stderr
    both = [(f"{r}/ExampleEvent", n) for n in range(N) for r in ("robotA", "robotB")]
    assert topics_and_seqs(merged) == both
    cut = tmp_path / "cut.mcap"
    done = run_miro(
        "log",
        "cut",
        str(merged),
        str(cut),
        "--start",
        "0.05",
        "--end",
        "0.1",
        "--exclude",
        "robotB/*",
    )
    assert done.returncode == 0, done.stderr
    assert topics_and_seqs(cut) == [("robotA/ExampleEvent", n) for n in range(5, 11)]
    again = run_miro("log", "cut", str(merged), str(cut))
    assert again.returncode == 2 and "exists (use --force" in again.stderr
    itself = run_miro("log", "cut", str(merged), str(merged), "-f")
    assert itself.returncode == 2 and "is one of the inputs" in itself.stderr
    nothing = run_miro("log", "cut", str(merged), str(cut), "-f", "--topics", "robot9/*")
    assert nothing.returncode == 0 and "no topic matches robot9/*" in nothing.stderr
    assert topics_and_seqs(cut) == []


def test_cut_repairs_a_log_whose_recorder_was_killed(tmp_path: Path) -> None:
    """Miro's LogTruncate: what a killed recorder left, written whole with its index."""
    killed = write_log(
        tmp_path / "killed.mcap",
        [("robot1", n, n) for n in range(300)],
        chunk_every=100,
        finish=False,
    )
    data = killed.read_bytes()
    killed.write_bytes(data + data[-50:-20])  # and a record cut off at the end
    fixed = tmp_path / "fixed.mcap"
    done = run_miro("log", "cut", str(killed), str(fixed))
    assert done.returncode == 0, done.stderr
    assert "warning: truncated inside a record" in done.stderr
    assert f"{fixed}: 300 events" in done.stderr
    assert topics_and_seqs(fixed) == [("robot1/ExampleEvent", n) for n in range(300)]
    info = run_miro("log", "info", str(fixed))
    assert info.returncode == 0 and "(finished)" in info.stdout and info.stderr == ""
