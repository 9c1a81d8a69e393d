"""services/gps_position.py: positions at a fixed rate, whatever rate the GPS readings come at."""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
import time

import Miro
from loopback import NamingProcess, Recorder, RunningServer, eventually, service_env
from repo_paths import REPO

from miro_gen import EventChannelFactory, StructuredPushSupplier

SERVICE = REPO / "services" / "gps_position.py"


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

        # Positions come from the service's own timer, not from the readings (counted between
        # pushes, not in seconds, so that a loaded machine cannot fail it): several between two
        # readings a second apart, where one a reading would give one; fewer than the readings
        # when these come at 50 Hz, where one a reading would give as many.
        pushed = []
        for n in range(3):  # readings at 1 Hz
            pushed.append(time.time())
            gps.push("Gps", fix(0.001 * (n + 1), 90.0))
            time.sleep(1.0)
        slow = [count_between(positions, a, b) for a, b in itertools.pairwise(pushed)]
        assert min(slow) >= 3, slow  # 10 expected in each second
        start, readings = time.time(), 0
        while time.time() < start + 1:  # readings at 50 Hz
            gps.push("Gps", fix(0.003, 90.0))
            readings += 1
            time.sleep(0.02)
        end = time.time()
        fast = count_between(positions, start, end)
        assert fast < readings * 0.75, (fast, readings)  # 10 and 50 expected
        eventually(lambda: positions.events[-1].publish_time > end, 30)  # from the last reading
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
