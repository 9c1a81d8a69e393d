"""`miro echo` and `miro hz` against a real channel: decoded events, rates and sequence gaps."""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Iterator

import Miro
import pytest
from eventlog_helpers import miro, stop
from loopback import NamingProcess, RunningServer, eventually

from miro_gen.eventlog.replay import ReplaySupplier


@pytest.fixture(scope="module")
def naming() -> Iterator[str]:
    process = NamingProcess(options=("--channel", "EventChannel"))
    yield process.endpoint
    process.stop()


@pytest.fixture
def supplier(naming: str) -> Iterator[ReplaySupplier]:
    running = RunningServer(naming, "robot5")
    yield ReplaySupplier(running.server.resolve_channel("EventChannel"))
    running.stop()


def event(n: int) -> Miro.ExampleEventIDL:
    return Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), 0.5))


def test_echo_prints_decoded_events_and_gaps(naming: str, supplier: ReplaySupplier) -> None:
    echo = miro("echo", "robot5/ExampleEvent", "-n", "5", "--naming", naming)
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    for seq in (0, 1, 2, 5, 6):  # 3 and 4 never arrive
        data = event(seq).serialize()
        now = time.time_ns()
        supplier.push_encoded(
            "robot5", "ExampleEvent", event(seq)._type_hash, 77, seq, now, now, data
        )
    try:
        out, err = echo.communicate(timeout=20)
    finally:
        if echo.poll() is None:
            echo.kill()
    assert echo.returncode == 0, err
    lines = out.splitlines()
    assert len(lines) == 6, out
    assert lines[3] == "-- 2 missed on robot5/ExampleEvent before #5"
    for line, seq in zip(lines[:3] + lines[4:], (0, 1, 2, 5, 6), strict=True):
        assert re.fullmatch(r"\d\d:\d\d:\d\d\.\d{6} robot5/ExampleEvent #\d+ .*", line)
        assert line.endswith(f"#{seq} {event(seq)!r}")


def test_hz_prints_the_rate_and_period_spread(naming: str, supplier: ReplaySupplier) -> None:
    hz = miro("hz", "*/ExampleEvent", "--naming", naming)
    eventually(lambda: supplier.has_subscribers("ExampleEvent"))
    due = time.monotonic()
    for n in range(60):  # 50 Hz for 1.2 s
        due += 0.02
        time.sleep(max(0.0, due - time.monotonic()))
        supplier.push("ExampleEvent", event(n))
    time.sleep(1.2)
    out, err = stop(hz, signal.SIGINT)
    assert hz.returncode == 0, err
    reports = re.findall(
        r"robot5/ExampleEvent: ([\d.]+) Hz  min ([\d.]+) s  max ([\d.]+) s  std ([\d.]+) s  "
        r"window (\d+)  lag ([\d.]+) ms \(max ([\d.]+)\)  missed (\d+)",
        out,
    )
    assert reports, out
    rate, low, high, std, window, lag, lag_max, missed = reports[-1]
    assert 40 < float(rate) < 60
    assert float(low) <= 0.02 <= float(high) and float(std) < 0.01
    assert int(window) >= 50 and missed == "0"
    assert 0 <= float(lag) <= float(lag_max)


def test_a_topic_is_required() -> None:
    result = miro("hz")
    _, err = result.communicate(timeout=20)
    assert result.returncode == 2 and "usage: miro hz" in err
