"""Keep-all means what it says: a keep-all consumer process gets every one of 100,000 small
events while two busy processes take the machine's cores, the channel's queues and its own
holding them until it reads them. Counted, not timed."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator

import pytest
from loopback import NamingProcess, eventually, service_env
from miro_cli import REPO

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


@pytest.mark.xfail(
    reason="issue 29, not done: the channel's proxy still drops toward a keep-all consumer whose "
    "process is not scheduled for long (64 frames per consumer; 409 of 100,000 lost at load 8)",
    strict=False,
)
def test_a_keep_all_consumer_loses_none_of_100000_events_beside_two_busy_processes(
    busy_cores: None,
) -> None:
    naming = NamingProcess(options=("--channel", "Ticks"))
    env = service_env()
    started = []
    try:
        counter = subprocess.Popen(
            [sys.executable, PROCS, "count", naming.endpoint, "Ticks"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        started.append(counter)
        assert counter.stdout is not None and counter.stdin is not None
        assert counter.stdout.readline().strip() == "READY"
        flooder = subprocess.Popen(
            [sys.executable, PROCS, "flood", naming.endpoint, "Ticks", str(EVENTS), RATE],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        started.append(flooder)
        assert flooder.stdout is not None
        sent = flooder.stdout.readline().split()
        assert sent[0] == "SENT", sent

        def stats() -> list[int]:
            assert counter.stdin is not None and counter.stdout is not None
            counter.stdin.write("STATS\n")
            counter.stdin.flush()
            return [int(w) for w in counter.stdout.readline().split()[1:]]

        eventually(lambda: sum(stats()) >= EVENTS, 120)
        received, missed, dropped = stats()
        assert (int(sent[1]), int(sent[2])) == (EVENTS, 0)  # the supplier dropped none
        assert (received, missed, dropped) == (EVENTS, 0, 0)
    finally:
        for p in started:
            p.kill()
            p.wait()
        naming.stop()
