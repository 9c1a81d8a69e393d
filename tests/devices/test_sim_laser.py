"""`miro sim laser` publishing scans on a channel, and `miro hz` showing their rate and
bandwidth: real processes, a real naming service and channel."""

from __future__ import annotations

import re
import signal
from array import array
from collections.abc import Iterator

import Miro
import pytest
from eventlog_helpers import miro, stop
from loopback import NamingProcess, Recorder, RunningServer, eventually, run_miro

from miro_gen.eventlog.rates import RateWindow, data_rate
from miro_gen.sim.laser import LaserScans

RS = Miro.RangeSensor


@pytest.fixture(scope="module")
def naming() -> Iterator[str]:
    process = NamingProcess(options=("--channel", "EventChannel"))
    yield process.endpoint
    process.stop()


def test_scans_see_the_room_and_the_moving_pillar() -> None:
    scans = LaserScans()
    first = scans.scan(0)
    assert len(first) == 1081 and first.typecode == "i"
    assert all(23 <= r <= 60000 or r == RS.HORIZON_RANGE for r in first)
    assert scans.scan(scans.cycle) is first  # the pillar's motion repeats: computed once
    assert scans.scan(scans.cycle // 4) != first
    front = first[540]  # straight ahead: the pillar, 1.5 m away, minus its radius
    assert 1300 <= front <= 1400
    assert len(LaserScans(beams=361, rate=10).scan(3)) == 361


def test_sim_laser_publishes_scans_and_hz_shows_rate_and_bandwidth(naming: str) -> None:
    gui = RunningServer(naming, "gui")
    events = Recorder(gui.server.resolve_channel("EventChannel"))
    events.set_subscriptions([("rover", "Laser")])
    sim = miro("sim", "laser", "--naming", naming, "-MNC", "rover")
    hz = miro("hz", "rover/Laser", "--naming", naming)
    try:
        eventually(lambda: len(events.events) >= 60, 30)
        scans = [e.payload for e in events.events]
        assert all(type(s) is Miro.RangeScanEventIDL and len(s.range) == 1 for s in scans)
        assert all(type(s.range[0]) is array and len(s.range[0]) == 1081 for s in scans)
        assert len({s.range[0].tobytes() for s in scans}) > 1  # the pillar moves
        seqs = [e.seq for e in events.events]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs))) and events.missed == 0
        stamps = [e.stamp for e in events.events]
        assert stamps == sorted(stamps)
        times = [s.time.sec + s.time.usec / 1e6 for s in scans]
        assert all(abs(t - e.stamp) < 1e-5 for t, e in zip(times, events.events, strict=True))
        payload = len(scans[0].serialize())
        eventually(lambda: hz.poll() is None and len(events.events) >= 120, 30)
    finally:
        out, err = stop(hz, signal.SIGINT)
        sim_out, sim_err = stop(sim, signal.SIGINT)
        gui.stop()
    assert sim.returncode == 0, sim_err
    assert sim_out.startswith("laser: 1081 beams at 40 Hz as rover/Laser on EventChannel")
    assert re.search(r"published \d+ scans", sim_out), sim_out
    reports = re.findall(r"rover/Laser: ([\d.]+) Hz .* missed (\d+)  ([\d.]+) (kB|MB)/s", out)
    assert reports, out + err
    rate, missed, bandwidth, unit = reports[-1]
    # Every scan has the same size: bandwidth / rate is that size (whatever the rate was).
    per_scan = float(bandwidth) * (1e3 if unit == "kB" else 1e6) / float(rate)
    assert abs(per_scan - payload) / payload < 0.01 and missed == "0"


def test_sim_laser_refuses_a_bad_command_line_in_one_line() -> None:
    result = run_miro("sim", "laser", "--beams", "1")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "miro sim laser: --beams must be 2 or more, --rate above 0, --duration not negative"
    ]
    assert "miro sim laser" in run_miro("sim", "laser", "--help").stdout
    assert "laser" in run_miro("sim", "--help").stdout


def test_bandwidth_over_the_window() -> None:
    window = RateWindow(3)
    assert window.bandwidth() is None
    for t, size in ((0.0, 999), (0.5, 100), (1.0, 200), (1.5, 300), (2.0, 400)):
        window.add(t, size)
    assert window.bandwidth() == (200 + 300 + 400) / 1.5  # the last 3 periods
    assert data_rate(1_500_000) == "1.5 MB/s" and data_rate(12) == "12 B/s"
    assert data_rate(43_480) == "43.5 kB/s"
