"""The player's replay honours keep-all consumers' credits (eventlog.replay, transport.events
.credits), as a live supplier does: at x32 a keep-all consumer process slower than the replay,
with a spin loop beside it, receives every event in order; the player's clock waits for a
send that holds it (`held_back`); a keep-last consumer is not waited for; a keep-all consumer
killed mid-replay holds the player back once at most (the bound), not per event. Counted, not
timed."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from eventlog_helpers import PROCS, write_log
from loopback import eventually, service_env

from miro_gen import Server
from miro_gen.eventlog.fileset import Event, FileSet
from miro_gen.eventlog.player import Player
from miro_gen.eventlog.routes import Routes
from miro_gen.transport import shm
from miro_gen.transport.events.frames import topic

pytestmark = pytest.mark.skipif(not shm.available(), reason="credits need Linux memfd")

N = 4000  # events of robotA and robotB in turn, 1 ms apart: 4 s of log, 1/8 s at x32
DELAY = "0.0003"  # s a slow consumer takes per event: 1.2 s for them all, ten times x32's pace


@pytest.fixture
def spinner() -> Iterator[None]:
    """A second process busy beside the consumer (a spin loop)."""
    p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    yield
    p.kill()
    p.wait()


class Counter:
    """tests/procs/replay_counter.py on robotA's channel (robotB's too: the same)."""

    def __init__(self, naming: str, depth: int, delay: str = DELAY) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(PROCS / "replay_counter.py"), "--naming", naming,
             "-MNC", "robotA", "EventChannel", str(depth), delay],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=service_env(),
        )  # fmt: skip
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "READY"

    def first(self) -> None:
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "FIRST"

    def stats(self) -> list[int]:
        """received, missed, dropped, in order (1/0)."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write("STATS\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline().split()
        while line == ["FIRST"]:  # (printed at its first event, unread)
            line = self.proc.stdout.readline().split()
        assert line and line[0] == "STATS", line
        return [int(w) for w in line[1:]]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)


@pytest.fixture
def log(tmp_path: Path) -> Path:
    """Two robots in turn, 1 ms apart: two topics share the channel's queue toward a consumer."""
    events = [("robotB" if n % 2 else "robotA", n // 2, n) for n in range(N)]
    return write_log(tmp_path / "robots.mcap", events, chunk_every=500)


def player_of(server: Server, log: Path, rate: float = 32.0) -> tuple[Routes, Player]:
    """A player of `log` at `rate` into one channel it hosts, bound as robotA/EventChannel
    and robotB/EventChannel."""
    routes = Routes(server, mode="unified")
    assert routes.connect(["robotA", "robotB"]) == []
    files = FileSet()
    files.add(str(log))
    return routes, Player(files, routes.send, rate=rate)


def play(routes: Routes, player: Player, keep_all: int) -> None:
    """Play once a consumer subscribes, and `keep_all` keep-all consumers credit the topic."""
    supplier = routes.routes["robotA"].supplier
    frame = topic("robotA", "ExampleEvent")
    eventually(lambda: routes.subscribed("robotB", "ExampleEvent"), 30)
    eventually(lambda: len(supplier._keep_all.matching(frame)) >= keep_all, 30)
    player.start()
    player.play()


def test_a_keep_all_consumer_receives_every_replayed_event_in_order_at_x32(
    server: Server, naming: str, log: Path, spinner: None
) -> None:
    routes, player = player_of(server, log)
    counter = Counter(naming, 0)
    try:
        play(routes, player, keep_all=1)
        assert player.ended.wait(120)
        eventually(lambda: counter.stats()[0] >= N, 60, lambda: str(counter.stats()))
        assert counter.stats() == [N, 0, 0, 1]  # every one, in order, none missed
        supplier = routes.routes["robotA"].supplier
        assert (supplier.replayed, supplier.replay_dropped, supplier.replay_unwaited) == (N, 0, 0)
        assert supplier.replay_waited > 0  # the consumer's credits held the player back
    finally:
        player.close()
        player.files.close()
        counter.stop()


def test_a_keep_last_consumer_does_not_hold_the_replay_back(
    server: Server, naming: str, log: Path
) -> None:
    routes, player = player_of(server, log)
    counter = Counter(naming, 10)
    try:
        play(routes, player, keep_all=0)
        assert player.ended.wait(120)
        supplier = routes.routes["robotA"].supplier
        assert (supplier.replay_waited, supplier.replay_unwaited) == (0, 0)  # never waited
        assert supplier.replayed + supplier.replay_dropped == N
        eventually(lambda: counter.stats()[0] > 0, 60)
        assert counter.stats()[3] == 1  # what it got came in order
    finally:
        player.close()
        player.files.close()
        counter.stop()


def test_a_killed_keep_all_consumer_holds_the_replay_back_once_at_most(
    server: Server, naming: str, log: Path
) -> None:
    """Killed (kill -9) at its first event, with the replay held back by its credits: the
    player stops waiting for it at most once per topic (its table's process is gone, or its
    subscription is), and a keep-all consumer beside it still gets every event."""
    routes, player = player_of(server, log)
    doomed = Counter(naming, 0, delay="0.01")  # a hundred events a second: far behind
    beside = Counter(naming, 0)
    try:
        play(routes, player, keep_all=2)
        doomed.first()
        doomed.proc.send_signal(signal.SIGKILL)
        assert player.ended.wait(120)
        supplier = routes.routes["robotA"].supplier
        assert (supplier.replayed, supplier.replay_dropped) == (N, 0)
        stalls = [c.flow.stalls for c in supplier._credits.values()]  # a topic per robot
        assert max(stalls) <= 1, stalls  # given up once at most in each, not per event
        eventually(lambda: beside.stats()[0] >= N, 60, lambda: str(beside.stats()))
        assert beside.stats() == [N, 0, 0, 1]
    finally:
        player.close()
        player.files.close()
        doomed.stop()
        beside.stop()


def test_the_clock_waits_for_a_send_that_holds_the_player(tmp_path: Path) -> None:
    """A send that holds the play thread (credits that do not come) sets the clock back to
    that event's time, once, and says so; the events after it keep their spacing."""
    log = write_log(tmp_path / "a.mcap", [("robotA", n, 10 * n) for n in range(20)])
    files = FileSet()
    files.add(str(log))
    sent: list[int] = []

    def send(event: Event) -> None:
        sent.append(event.message.sequence)
        if event.message.sequence == 5:
            time.sleep(0.5)  # over twice HELD: held back, however loaded the machine

    player = Player(files, send)
    try:
        player.start()
        player.play()
        assert player.ended.wait(60)
    finally:
        player.close()
        files.close()
    assert sent == list(range(20))
    assert player.held_back >= 1
