"""The log tools on a terminal (a pseudo-terminal here): the player's keys and progress bar,
the recorder's progress line."""

from __future__ import annotations

import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from eventlog_helpers import proc, read_events, stop
from loopback import NamingProcess, service_env
from test_log_clock import synthetic_log


@pytest.fixture(scope="module")
def naming() -> Iterator[str]:
    process = NamingProcess(options=("--channel", "EventChannel"))
    yield process.endpoint
    process.stop()


class Terminal:
    """`miro ARGS` with a pseudo-terminal as its stdin and stderr."""

    def __init__(self, *args: str, cwd: Path | None = None) -> None:
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "miro_gen.cli.main", *args],
            stdin=slave,
            stdout=subprocess.DEVNULL,
            stderr=slave,
            env=service_env(),
            cwd=cwd,
        )
        os.close(slave)
        self.screen = ""

    def read_until(self, check: Callable[[str], object], seconds: float = 30) -> str:
        """The screen once check(screen) is true (it has printed what the test waits for);
        fails after `seconds` or when the process has exited without it."""
        end = time.monotonic() + seconds
        while not check(self.screen):
            left = end - time.monotonic()
            assert left > 0, f"not on the screen in {seconds} s: {self.screen!r}"
            ready, _, _ = select.select([self.master], [], [], left)
            if ready:
                try:
                    self.screen += os.read(self.master, 4096).decode(errors="replace")
                except OSError:  # it has exited
                    assert check(self.screen), f"exited without it: {self.screen!r}"
        return self.screen

    def key(self, ch: str) -> None:
        os.write(self.master, ch.encode())

    def close(self) -> int:
        code = self.proc.wait(20)
        os.close(self.master)
        return code


def received(printer: subprocess.Popen[str]) -> int:
    return len(read_events(stop(printer, signal.SIGTERM)[0]))


def test_space_pauses_s_steps_and_q_quits(naming: str, tmp_path: Path) -> None:
    log = tmp_path / "ten_seconds.mcap"
    synthetic_log(log, 10)  # 41 events, one every 0.25 s
    printer = proc("event_printer.py", "--naming", naming, "-MNC", "gui", "EventChannel")
    assert printer.stdout is not None and printer.stdout.readline().strip() == "READY"
    term = Terminal("log", "play", str(log), "--naming", naming, "-MNC", "robot1")
    try:
        term.read_until(lambda screen: "[#" in screen)  # the bar fills as it plays
        assert "playing " in term.screen and " events  x1" in term.screen
        term.key(" ")
        term.read_until(lambda screen: "paused (space: resume, s: step)" in screen)
        at_pause = shown_events(term.screen)  # (one more may have been on its way)
        before = term.screen.count("\r")
        term.key("s")
        term.key("s")
        term.read_until(lambda screen: shown_events(screen) >= at_pause + 2)
        term.key("q")
        term.read_until(lambda screen: "replayed " in screen)
        assert term.close() == 0
        assert term.screen.count("\r") > before
    finally:
        if term.proc.poll() is None:
            term.proc.kill()
        got = received(printer)
    # Paused, then two steps of one event each: what was sent by the pause and two more, far
    # fewer than the 41 logged.
    summary = int(term.screen.rsplit("replayed ", 1)[1].split()[0])
    assert got == summary
    assert at_pause + 2 <= summary <= at_pause + 3 and summary < 41


def shown_events(screen: str) -> int:
    """The count of sent events on the player's last paused status line."""
    found = re.findall(r"(\d+) events  x1 paused", screen)
    return int(found[-1]) if found else -1


def test_the_recorder_shows_its_progress(naming: str, tmp_path: Path) -> None:
    path = tmp_path / "progress.mcap"
    term = Terminal("log", "record", "--naming", naming, "-o", path.name, cwd=tmp_path)
    try:
        term.read_until(lambda screen: "recording " in screen)
        sup = proc("event_supplier.py", "--naming", naming, "-MNC", "robot9", "EventChannel", "30")
        sup.communicate(timeout=30)
        screen = term.read_until(lambda screen: "30 events" in screen)
        assert "\rrecording " in screen and "/s, " in screen
        term.proc.send_signal(signal.SIGINT)
        term.read_until(lambda screen: f"{path.name}: 30 events in" in screen)
        assert term.close() == 0
        assert f"{path.name}: 30 events in" in term.screen
    finally:
        if term.proc.poll() is None:
            term.proc.kill()
