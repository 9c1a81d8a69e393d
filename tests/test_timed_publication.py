"""services/gps_position.py: positions at a fixed rate, whatever rate the GPS readings come at."""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import Miro
from loopback import NamingProcess, Recorder, RunningServer, eventually, service_env

from miro_gen import EventChannelFactory, StructuredPushSupplier

SERVICE = Path(__file__).resolve().parents[1] / "services" / "gps_position.py"


def fix(north_deg: float, course: float) -> Miro.GpsDataIDL:
    return Miro.GpsDataIDL(valid=True, latitude=45.0 + north_deg, longitude=-75.0, course=course)


def count_between(r: Recorder, start: float, end: float) -> int:
    return sum(1 for e in r.events if start <= e.publish_time < end)


def test_positions_at_ten_hertz_from_readings_at_one_and_at_fifty() -> None:
    naming = NamingProcess()
    rover = RunningServer(naming.endpoint, "rover")
    proc = None
    try:
        channel = EventChannelFactory(rover.server).create_channel()
        gps = StructuredPushSupplier(channel)
        positions = Recorder(channel)
        positions.set_subscriptions([("rover", "Position")])
        proc = subprocess.Popen(
            [sys.executable, str(SERVICE), "--naming", naming.endpoint, "-MNC", "rover"],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        assert proc.stdout is not None and "at 10 Hz" in proc.stdout.readline()
        eventually(lambda: gps.has_subscribers("Gps"))
        gps.push("Gps", fix(0.0, 0.0))
        eventually(lambda: len(positions.events) > 0)

        start = time.time()  # readings at 1 Hz for 3 s
        for n in range(3):
            gps.push("Gps", fix(0.001 * (n + 1), 90.0))
            time.sleep(1.0)
        slow = count_between(positions, start + 0.5, start + 2.5)
        start = time.time()  # readings at 50 Hz for 2 s
        while time.time() < start + 2:
            gps.push("Gps", fix(0.003, 90.0))
            time.sleep(0.02)
        fast = count_between(positions, start + 0.5, start + 1.5)
        assert 16 <= slow <= 24, slow  # 20 expected in 2 s
        assert 7 <= fast <= 13, fast  # 10 expected in 1 s
        last = positions.events[-1].payload
        assert isinstance(last, Miro.PositionIDL)
        assert math.isclose(last.point.y, math.radians(0.003) * 6_371_000_000, rel_tol=1e-6)
        assert abs(last.point.x) < 1e-3
        assert math.isclose(last.heading, 0.0, abs_tol=1e-9)  # course 90 (east): heading 0
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(10)
        rover.stop()
        naming.stop()
