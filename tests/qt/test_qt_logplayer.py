"""The player window (`miro log player`), headless, driven as a user drives it (QTest clicks and
keys), against a real naming service, the channels it binds and consumer processes in each
robot's naming context. Every test checks what the consumers receive: play and pause, seeks
on the timeline and the slider, speed changes (on the player's clock channel), steps back,
topics left out, two robots' logs merged into robotA/EventChannel and robotB/EventChannel
(files opened and closed while it plays), and a cut saved as a new log that holds exactly
the cut's events and replays them.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zmq
from eventlog_helpers import T0, read_events, write_log
from loopback import run_miro, service_env
from qt_procs import ServiceProcess
from qt_support import QFileDialog, QPoint, Qt, QTest, application, qt_run, qt_wait

from miro_gen import Server
from miro_gen.eventlog.fileset import FileSet, at_time
from miro_gen.eventlog.player import RATES, Player
from miro_gen.eventlog.routes import ClockPublisher, Routes
from miro_gen.qt import QtEventBridge
from miro_gen.qt.logplayer import SLIDER_STEPS, LogPlayerWindow

N = 100  # events of each robot, 50 ms apart, robotB 25 ms after robotA: 5 s at 1x
A, B = ("robotA", "ExampleEvent"), ("robotB", "ExampleEvent")
MS = 1_000_000


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("logs")
    a = write_log(folder / "robotA.mcap", [("robotA", n, 50 * n) for n in range(N)], chunk_every=16)
    b = write_log(
        folder / "robotB.mcap", [("robotB", n, 50 * n + 25) for n in range(N)], chunk_every=16
    )
    return a, b


class Rig:
    """The player's process side: a Server whose reactor runs in a Qt bridge, the robots'
    channels and the clock channel (context `player`)."""

    def __init__(self, naming: str) -> None:
        application()
        self.naming = naming
        self.server = Server(
            ["logplayer-test", "--naming", naming, "-MNC", "player"], context=zmq.Context()
        )
        self.routes = Routes(self.server)
        self.clock = ClockPublisher(self.server)
        self.bridge = QtEventBridge(self.server)
        self.bridge.start()
        self.started: list[ServiceProcess] = []

    def window(self, *paths: Path) -> LogPlayerWindow:
        files = FileSet()
        player = Player(files, self.routes.send, self.clock)
        window = LogPlayerWindow(player, self.routes)
        window.resize(1200, 800)
        window.show()
        player.start()
        assert window.open_files([str(p) for p in paths]) == len(paths)
        QTest.qWaitForWindowExposed(window)
        qt_run(0.1)  # laid out: its rows have their places, to be clicked
        return window

    def consumer(self, context: str, channel: str = "EventChannel") -> ServiceProcess:
        """A consumer process of `channel` in `context`, subscribed before it returns (stopped
        at the end of the test)."""
        p = ServiceProcess(
            "tests/procs/event_printer.py", "--naming", self.naming, "-MNC", context, channel
        )
        self.started.append(p)
        p.wait_line("READY", 30)
        if channel == "EventChannel":
            qt_wait(lambda: self.routes.subscribed(context, "ExampleEvent"), 30)
        return p


@pytest.fixture(scope="module")
def rig(naming: str) -> Iterator[Rig]:
    r = Rig(naming)
    yield r
    r.bridge.stop()


@pytest.fixture(autouse=True)
def stop_consumers(rig: Rig) -> Iterator[None]:
    """The consumer processes a test started are stopped after it, whatever happened."""
    yield
    for p in rig.started:
        p.stop()
    rig.started.clear()


@pytest.fixture
def opened(rig: Rig) -> Iterator[Callable[..., LogPlayerWindow]]:
    made: list[LogPlayerWindow] = []

    def open_window(*paths: Path) -> LogPlayerWindow:
        made.append(rig.window(*paths))
        return made[-1]

    yield open_window
    for w in made:
        w.player.close()
        w.close()
        w.files.close()


def events(p: ServiceProcess) -> list[dict[str, Any]]:
    return read_events("\n".join(p.lines))


def seqs(p: ServiceProcess) -> list[tuple[str, int]]:
    return [(e["domain"], e["seq"]) for e in events(p)]


def wait_events(p: ServiceProcess, count: int) -> list[tuple[str, int]]:
    qt_wait(lambda: len(events(p)) >= count, 60)
    return seqs(p)


def click(widget: Any, pos: QPoint | None = None) -> None:
    if pos is None:
        QTest.mouseClick(widget, Qt.MouseButton.LeftButton)
    else:
        QTest.mouseClick(widget, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, pos)
    application().processEvents()


def key(
    window: LogPlayerWindow,
    k: Qt.Key,
    modifier: Qt.KeyboardModifier = Qt.KeyboardModifier.NoModifier,
) -> None:
    QTest.keyClick(window, k, modifier)
    application().processEvents()


def expected(
    window: LogPlayerWindow, start_ns: int, domain: str | None = None
) -> list[tuple[str, int]]:
    """The events from log time `start_ns` on, as the model has them."""
    return [
        (e.topic.domain, e.message.sequence)
        for e in window.files.forward(at_time(start_ns))
        if domain is None or e.topic.domain == domain
    ]


def test_play_pause_and_a_faster_speed(
    rig: Rig, opened: Callable[..., LogPlayerWindow], logs: tuple[Path, Path]
) -> None:
    window = opened(logs[0])
    robot = rig.consumer("robotA")
    clock = rig.consumer("player", "LogClock")
    try:
        click(window.play_button)
        assert wait_events(robot, 3)[:3] == [("robotA", n) for n in range(3)]
        click(window.pause_button)
        assert window.player.paused
        sent = window.player.sent
        qt_wait(lambda: len(events(robot)) == sent)
        qt_run(0.5)  # paused: nothing more comes
        assert len(events(robot)) == sent < N
        assert "paused" in window.sent_label.text()
        window.dial.setValue(RATES.index(2.0))  # the speed dial turned, as a user turns it
        key(window, Qt.Key.Key_Plus)  # and once more from the keyboard
        assert window.player.rate == 4.0 and window.speed_label.text() == "x4"
        key(window, Qt.Key.Key_Space)  # plays on, at x4
        assert wait_events(robot, N) == [("robotA", n) for n in range(N)]  # each once, in order
        qt_wait(lambda: window.player.at_end)
        rates = [e["payload"] for e in events(clock)]
        assert any("rate=2.0" in r for r in rates) and "rate=4.0" in rates[-1]
        first_fast = next(i for i, r in enumerate(rates) if "rate=4.0" in r)
        assert "paused=False" in "".join(rates[first_fast:])  # it played at x4
    finally:
        robot.stop()
        clock.stop()


def test_seek_on_the_timeline_and_the_slider_then_step_both_ways(
    rig: Rig, opened: Callable[..., LogPlayerWindow], logs: tuple[Path, Path]
) -> None:
    window = opened(*logs)
    robot_a, robot_b = rig.consumer("robotA"), rig.consumer("robotB")
    try:
        track = window.timeline.tracks[A]
        x = track.width() // 2
        click(track, QPoint(x, track.height() // 2))  # seek to the middle, paused
        target = track.time_at(x)
        assert window.player.log_now() == target
        want: dict[str, list[tuple[str, int]]] = {"robotA": [], "robotB": []}
        consumers = {"robotA": robot_a, "robotB": robot_b}

        def received_as_sent(*sent: tuple[str, int]) -> None:
            for event in sent:
                want[event[0]].append(event)
            for robot, consumer in consumers.items():
                assert wait_events(consumer, len(want[robot])) == want[robot]

        key(window, Qt.Key.Key_Right)  # the next event: the first at or after the seek
        received_as_sent(expected(window, target)[0])
        window.slider.setValue(SLIDER_STEPS // 4)  # the slider, a quarter in
        start, end = window.files.cut
        quarter = start + (end - start) // 4
        assert window.player.log_now() == quarter
        both = expected(window, quarter)
        for _ in range(3):
            key(window, Qt.Key.Key_Right)
        received_as_sent(*both[:3])
        key(window, Qt.Key.Key_Left)  # a step back: the one before the last sent
        received_as_sent(both[1])
        key(window, Qt.Key.Key_Left)  # and another
        received_as_sent(both[0])
        key(window, Qt.Key.Key_Right)  # forward again: the one after it
        received_as_sent(both[1])
        window.refresh()  # the event list, as its timer shows it
        table = window.events
        rows = table.model_rows.rows
        assert [(r.topic.domain, r.sequence) for r in rows[-2:]] == [both[0], both[1]]
        clicked = rows[-3]  # an event list row: the player moves to that event
        cell = table.visualRect(table.model_rows.index(len(rows) - 3, 1))
        click(table.viewport(), cell.center())
        assert window.player.position == clicked.key
        assert window.inspector.shown is not None and window.inspector.shown.key == clicked.key
        key(window, Qt.Key.Key_Right)  # and it is the next one played
        received_as_sent((clicked.topic.domain, clicked.sequence))
        here = window.player.log_now()
        key(window, Qt.Key.Key_Right, Qt.KeyboardModifier.ShiftModifier)  # seeks a 20th on
        assert window.player.log_now() == here + (end - start) // 20
        key(window, Qt.Key.Key_Right)
        received_as_sent(expected(window, here + (end - start) // 20)[0])
    finally:
        robot_a.stop()
        robot_b.stop()


def test_a_topic_left_out_is_not_played_and_comes_back(
    rig: Rig, opened: Callable[..., LogPlayerWindow], logs: tuple[Path, Path]
) -> None:
    window = opened(*logs)
    robot_a, robot_b = rig.consumer("robotA"), rig.consumer("robotB")
    try:
        box = window.timeline.boxes[B]
        click(box)  # unchecked: robotB's events are left out
        assert not box.isChecked() and window.files.excluded == {B}
        robot_b_menu = next(a for a in window.events_menu.actions() if a.text() == "robotB").menu()
        assert not robot_b_menu.actions()[0].isChecked()  # the Events menu says so too
        window.dial.setValue(RATES.index(32.0))
        click(window.play_button)
        assert wait_events(robot_a, N) == [("robotA", n) for n in range(N)]
        qt_wait(lambda: window.player.at_end)
        assert events(robot_b) == []
        robot_b_menu.actions()[0].trigger()  # back in, from the menu
        assert box.isChecked() and window.files.excluded == frozenset()
        click(window.play_button)  # at the end: again from the start
        assert wait_events(robot_b, N) == [("robotB", n) for n in range(N)]
    finally:
        robot_a.stop()
        robot_b.stop()


def test_two_robots_merged_into_their_channels_files_opened_and_closed_while_playing(
    rig: Rig, opened: Callable[..., LogPlayerWindow], logs: tuple[Path, Path]
) -> None:
    window = opened(logs[0])
    robot_a = rig.consumer("robotA")
    try:
        window.dial.setValue(RATES.index(1 / 4))  # 20 s for the log: slow enough to change it
        click(window.play_button)
        wait_events(robot_a, 2)
        assert window.open_files([str(logs[1])]) == 1  # robotB's log joins while it plays
        robot_b = rig.consumer("robotB")
        window.dial.setValue(RATES.index(32.0))
        got_a = wait_events(robot_a, N)
        got_b = wait_events(robot_b, 1)
        qt_wait(lambda: window.player.at_end)
        assert got_a == [("robotA", n) for n in range(N)]
        got_b = seqs(robot_b)
        assert got_b == [("robotB", n) for n in range(got_b[0][1], N)]  # from where it joined
        rows = [(r.topic.domain, r.sequence) for r in window.player.history.rows()]
        assert rows[-4:] == [("robotA", 98), ("robotB", 98), ("robotA", 99), ("robotB", 99)]
        window.close_file(str(logs[0]))  # robotA's log closed: only robotB's plays
        assert [t.name for t in window.files.topics()] == [B]
        assert list(window.timeline.tracks) == [B]
        before = len(events(robot_a))
        click(window.play_button)
        assert wait_events(robot_b, len(got_b) + N)[len(got_b) :] == [
            ("robotB", n) for n in range(N)
        ]
        qt_wait(lambda: window.player.at_end)
        assert len(events(robot_a)) == before
        assert rig.routes.channel_of("robotA") == "robotA/EventChannel"
        assert rig.routes.channel_of("robotB") == "robotB/EventChannel"
        assert "robotA/EventChannel, robotB/EventChannel" in window.channels_label.text()
        robot_b.stop()
    finally:
        robot_a.stop()


def test_cut_and_save_as_writes_exactly_the_cut(
    rig: Rig,
    opened: Callable[..., LogPlayerWindow],
    logs: tuple[Path, Path],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    window = opened(*logs)
    start = T0 + 1000 * MS
    window.player.seek(start)
    window.cut_front_action.trigger()  # Edit > Cut front, at 1 s
    window.player.seek(T0 + 3000 * MS)
    window.cut_back_action.trigger()  # Edit > Cut back, at 3 s
    assert window.files.cut == (start, T0 + 3000 * MS)
    click(window.timeline.boxes[B])  # robotB left out of the cut too
    saved = tmp_path / "cut.mcap"
    monkeypatch.setattr(QFileDialog, "getSaveFileName", lambda *a, **k: (str(saved), ""))
    window.save_action.trigger()  # File > Save cut as...
    qt_wait(lambda: saved.exists())
    assert f"saved 41 events to {saved}" in window.statusBar().currentMessage()
    cut = [("robotA", n) for n in range(20, 61)]  # 1 s to 3 s, both ends included
    robot_a = rig.consumer("robotA")
    try:
        played = run_miro(
            "log",
            "play",
            str(saved),
            "--naming",
            rig.naming,
            "--shared-channels",
            "--wait-subscribed",
            timeout=120,
        )
        assert played.returncode == 0, played.stderr
        assert wait_events(robot_a, len(cut)) == cut  # the saved log holds exactly the cut
    finally:
        robot_a.stop()
    window.undo_action.trigger()  # Edit > Undo: the back cut taken back
    assert window.files.cut == (start, T0 + (50 * (N - 1) + 25) * MS)
    window.undo_action.trigger()
    assert window.files.cut == window.files.span()


def test_the_command_plays_the_logs_and_ends_on_sigterm(
    rig: Rig, logs: tuple[Path, Path], tmp_path: Path
) -> None:
    """`miro log player FILE... --play` as a user starts it (offscreen here): robotA's events
    reach robotA's consumer (through the channel the rig has bound: it is used, not taken
    over), again and again with --loop; SIGTERM closes the window and the process ends."""
    robot_a = rig.consumer("robotA")
    window = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "log", "player", *map(str, logs),
         "--naming", rig.naming, "-MNC", "gui", "--play", "--loop", "--rate", "32"],
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(QT_QPA_PLATFORM="offscreen"),
    )  # fmt: skip
    try:
        got = wait_events(robot_a, 2 * N)  # a whole pass, at least, whatever it missed first
        assert {d for d, _ in got} == {"robotA"}
        passes = [s for _, s in got]
        assert any(passes[i : i + N] == list(range(N)) for i in range(len(passes) - N + 1))
    finally:
        window.send_signal(signal.SIGTERM)
        _, err = window.communicate(timeout=30)
    assert window.returncode == 0, err
    assert "Traceback" not in err


def test_the_command_without_a_display_says_so(logs: tuple[Path, Path]) -> None:
    env = service_env()
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        env.pop(name, None)
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "log", "player", str(logs[0])],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert done.returncode == 1
    assert done.stderr.startswith("miro log player: no display")
