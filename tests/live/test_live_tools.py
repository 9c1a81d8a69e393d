"""`miro echo` and `miro hz` against a real channel: decoded events, rates and sequence gaps."""

from __future__ import annotations

import re
import signal
import threading
import time
from collections.abc import Iterator

import Miro
import pytest
from eventlog_helpers import miro
from loopback import NamingProcess, RunningServer, eventually

from miro_gen.eventlog.rates import RateWindow
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


REPORT = re.compile(
    r"robot5/ExampleEvent: ([\d.]+) Hz  min ([\d.]+) s  max ([\d.]+) s  std ([\d.]+) s  "
    r"window (\d+)  lag ([\d.]+) ms \(max ([\d.]+)\)  missed (\d+)"
)


def test_hz_prints_the_rate_and_period_spread(naming: str, supplier: ReplaySupplier) -> None:
    hz = miro("hz", "*/ExampleEvent", "--naming", naming)
    try:
        assert hz.stdout is not None
        lines: list[str] = []
        threading.Thread(target=lambda: lines.extend(hz.stdout or ()), daemon=True).start()
        eventually(lambda: supplier.has_subscribers("ExampleEvent"))
        due = time.monotonic()
        for n in range(60):  # 50 Hz for 1.2 s
            due += 0.02
            time.sleep(max(0.0, due - time.monotonic()))
            supplier.push("ExampleEvent", event(n))
        # Its once-a-second report, once it has counted all 60 (59 periods).
        eventually(lambda: any((m := REPORT.search(x)) and m[5] == "59" for x in lines), 30)
        hz.send_signal(signal.SIGINT)
        assert hz.wait(20) == 0, hz.stderr.read() if hz.stderr else ""
    finally:
        if hz.poll() is None:  # a failed check leaves no `miro hz` behind
            hz.kill()
            hz.wait()
    reports = [m.groups() for x in lines if (m := REPORT.search(x))]
    rate, low, high, std, _, lag, lag_max, missed = next(r for r in reports if r[4] == "59")
    # The figures are of arrival times, which a loaded machine bends: the test checks what
    # they must say of each other (the mean period between the shortest and the longest, a
    # spread no wider than their range), and counts; test_rate_window_statistics checks the
    # arithmetic on known times.
    slack = 0.0001  # printed to 0.1 ms
    assert float(low) - slack <= 1 / float(rate) <= float(high) + slack
    assert float(std) <= float(high) - float(low) + slack
    assert missed == "0"
    assert 0 <= float(lag) <= float(lag_max)


def test_rate_window_statistics() -> None:
    """What `miro hz` prints, on arrival times given: 50 Hz with a late arrival."""
    window = RateWindow(100)
    assert window.stats() is None
    times = [0.02 * n for n in range(51)]
    times[10] += 0.01  # 10 ms late: one period of 30 ms, the next of 10 ms
    for t in times:
        window.add(t, lag=0.001)
    rate, low, high, std = window.stats() or (0.0, 0.0, 0.0, 0.0)
    assert rate == pytest.approx(50.0)
    assert low == pytest.approx(0.01) and high == pytest.approx(0.03)
    assert std == pytest.approx((2 * 0.01**2 / 50) ** 0.5)
    assert window.lag() == pytest.approx((0.001, 0.001))
    short = RateWindow(3)  # the last 3 periods only
    for t in (0.0, 1.0, 1.1, 1.2, 1.3):
        short.add(t)
    assert short.stats() == pytest.approx((10.0, 0.1, 0.1, 0.0), abs=1e-9)


def test_a_topic_is_required() -> None:
    result = miro("hz")
    _, err = result.communicate(timeout=20)
    assert result.returncode == 2 and "usage: miro hz" in err
