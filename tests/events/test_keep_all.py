"""Keep-all means what it says: a keep-all consumer process gets every one of 100,000 small
events while two busy processes take the machine's cores, its credits holding its suppliers
back (transport.events.credits) so that the channel's queue for it never overflows. A keep-all
consumer that is stopped or killed holds its supplier back once, for the stated bound, not per
event, and a keep-last consumer beside it gets the stream as before. Counted, not timed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest
from loopback import NamingProcess, eventually, service_env
from miro_cli import REPO

from miro_gen.transport import shm

pytestmark = pytest.mark.skipif(not shm.available(), reason="credits need Linux memfd")

PROCS = str(REPO / "tests" / "shm_procs.py")
EVENTS = 100_000
RATE = "200000"  # a second, in bursts of 20: thousands of small frames, not a few large ones


@pytest.fixture
def busy_cores() -> Iterator[None]:
    """A spin loop per core (two: the machine CI runs on), as `stress --cpu 2` would."""
    spinners = [
        subprocess.Popen([sys.executable, "-c", "while True: pass"])
        for _ in range(min(2, os.cpu_count() or 2))
    ]
    yield
    for p in spinners:
        p.kill()
        p.wait()


class Procs:
    """Processes of tests/shm_procs.py on a channel hosted by `miro naming --channel Ticks`."""

    def __init__(self) -> None:
        self.naming = NamingProcess(options=("--channel", "Ticks"))
        self.env = service_env()
        self.started: list[subprocess.Popen[str]] = []

    def start(self, *args: str) -> subprocess.Popen[str]:
        p = subprocess.Popen(
            [sys.executable, PROCS, args[0], self.naming.endpoint, "Ticks", *args[1:]],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=self.env,
        )  # fmt: skip
        self.started.append(p)
        return p

    def counter(self, depth: int = 0, topics: int = 1) -> subprocess.Popen[str]:
        c = self.start("count", str(depth), str(topics))
        assert c.stdout is not None
        assert c.stdout.readline().strip() == "READY"
        return c

    def close(self) -> None:
        for p in self.started:
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)
            p.kill()
            p.wait()
        self.naming.stop()


@pytest.fixture
def procs() -> Iterator[Procs]:
    p = Procs()
    yield p
    p.close()


def stats(counter: subprocess.Popen[str]) -> list[int]:
    """received, missed, dropped."""
    assert counter.stdin is not None and counter.stdout is not None
    counter.stdin.write("STATS\n")
    counter.stdin.flush()
    return [int(w) for w in counter.stdout.readline().split()[1:]]


def sent(flooder: subprocess.Popen[str]) -> list[int]:
    """sent, dropped, stalls (times it stopped waiting for a keep-all consumer), waited."""
    assert flooder.stdout is not None
    line = flooder.stdout.readline().split()
    assert line[0] == "SENT", line
    return [int(w) for w in line[1:]]


def test_a_keep_all_consumer_loses_none_of_100000_events_beside_two_busy_processes(
    busy_cores: None, procs: Procs
) -> None:
    counter = procs.counter()
    flooder = procs.start("flood", str(EVENTS), RATE)
    assert sent(flooder)[:2] == [EVENTS, 0]  # the supplier dropped none
    eventually(lambda: sum(stats(counter)) >= EVENTS, 120)
    assert stats(counter) == [EVENTS, 0, 0]


def test_a_keep_all_consumer_of_four_topics_loses_none_of_them_beside_two_busy_processes(
    busy_cores: None, procs: Procs
) -> None:
    """The channel's queue toward a consumer holds the frames of every topic it takes: the
    supplier's topics credited toward it share one window (before, each had its own, and four
    windows overflowed that queue: 275 and 1,368 lost in two runs)."""
    counter = procs.counter(topics=4)
    flooder = procs.start("flood", str(EVENTS), RATE, "0", "4")
    assert sent(flooder)[:2] == [EVENTS, 0]
    eventually(lambda: sum(stats(counter)) >= EVENTS, 120)
    assert stats(counter) == [EVENTS, 0, 0]


def go(flooder: subprocess.Popen[str], line: str = "GO") -> None:
    assert flooder.stdin is not None
    flooder.stdin.write(line + "\n")
    flooder.stdin.flush()


def test_a_stopped_keep_all_consumer_holds_its_supplier_back_once_and_not_a_keep_last_one(
    procs: Procs,
) -> None:
    """The keep-all consumer is stopped (SIGSTOP: alive, its credits unchanged) after the first
    event: the supplier waits for it once, for the bound, then sends on without it (not waiting
    again per event) and drops nothing; the keep-last consumer beside it gets the stream; the
    stopped one, let go on, counts every event it did not get in `missed` once a later one
    arrives."""
    stopped = procs.counter()
    keep_last = procs.counter(depth=10)
    flooder = procs.start("flood", "20000", RATE, "1")
    assert flooder.stdout is not None
    assert flooder.stdout.readline().strip() == "PUSHING"  # it takes the keep-all one's credits
    eventually(lambda: stats(stopped)[0] == 1, 60)
    stopped.send_signal(signal.SIGSTOP)
    go(flooder)
    sent_, dropped, stalls, _ = sent(flooder)
    assert (sent_, dropped) == (20000, 0)
    assert stalls == 1  # waited for the stopped consumer once, not per event or per frame
    # Every event reaches the keep-last consumer or is counted: received, skipped by its
    # queue (`dropped`), or lost at its own queue in the channel (`missed`, as before: one
    # more event shows what was lost at the end).
    go(flooder, "PUSH")
    assert sent(flooder)[:2] == [20001, 0]
    eventually(lambda: sum(stats(keep_last)) == 20001, 60, lambda: str(stats(keep_last)))
    stopped.send_signal(signal.SIGCONT)
    pushed = [20001]

    def accounted() -> bool:
        go(flooder, "PUSH")  # one more: what came before it and never arrived shows as a gap
        pushed[0] = sent(flooder)[0]
        return sum(stats(stopped)) == pushed[0]

    eventually(accounted, 60, lambda: f"{stats(stopped)} of {pushed[0]}")
    assert stats(stopped)[2] == 0  # what it did not get is in `missed` (if the channel's queue
    # held fewer than the frames sent meanwhile: large ones, all that waited the bound)


def test_a_killed_keep_all_consumer_does_not_hold_its_supplier_back(procs: Procs) -> None:
    """Killed (kill -9) just before the supplier pushes: its supplier stops waiting for it at
    most once (its table's process is gone, or its subscriptions are) and drops nothing; a
    keep-last consumer beside it gets the stream."""
    doomed = procs.counter()
    keep_last = procs.counter(depth=10)
    flooder = procs.start("flood", "50000", RATE, "1")
    assert flooder.stdout is not None
    assert flooder.stdout.readline().strip() == "PUSHING"
    doomed.kill()
    doomed.wait()
    go(flooder)
    sent_, dropped, stalls, _ = sent(flooder)
    assert (sent_, dropped) == (50000, 0)
    assert stalls <= 1
    go(flooder, "PUSH")  # one more: what the keep-last consumer lost at the end shows
    assert sent(flooder)[:2] == [50001, 0]
    eventually(lambda: sum(stats(keep_last)) == 50001, 60, lambda: str(stats(keep_last)))
