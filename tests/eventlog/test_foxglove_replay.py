"""`miro log play --foxglove`: a replay in Foxglove, whose playback controls drive the player.

A log of numbered FoxTest::Pose events 10 ms apart (written by the recorder's LogWriter) is
played by `miro log play --foxglove`; Foxglove's client (tests/foxglove/client.mjs) pauses it,
seeks into the middle and plays at double speed: the first event it then sees is the first
event of the log at or after the seek time, decoded with the log's omgidl schema, and a
process on `--clock log` (tests/procs/clocked_publisher.py) follows the jump.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import NamingProcess, Recorder, RunningServer, eventually, service_env
from miro_cli import REPO, run_miro_idl
from test_foxglove_bridge import FOXGLOVE, WAIT, Lines, _skip_reason

pytestmark = pytest.mark.skipif(_skip_reason() is not None, reason=str(_skip_reason()))
T0 = 1_700_000_000_000_000_000  # the log's first event, ns
STEP = 10_000_000  # ns between events
EVENTS = 400

WRITE_LOG = f"""
import sys, FoxTest
from miro_gen.eventlog.writer import LogWriter
from miro_gen.transport.events.frames import RawEvent
w = LogWriter(sys.argv[1])
for k in range({EVENTS}):
    pose = FoxTest.Pose(FoxTest.Point(k, -k), 0.5 * k, "log", [], FoxTest.Mode.PARK, k)
    t = {T0} + k * {STEP}
    w.write([RawEvent("robot1", "Pose", pose._type_hash, 1, k, t, t, pose.serialize())], t)
w.finish()
"""


class Replay:
    def __init__(self, folder: Path) -> None:
        generated = folder / "gen"
        compiled = run_miro_idl("-o", str(generated), str(FOXGLOVE / "FoxTest.idl"))
        assert compiled.returncode == 0, compiled.stderr
        env = service_env()
        env["PYTHONPATH"] = os.pathsep.join([str(generated), env["PYTHONPATH"]])
        self.log = folder / "poses.mcap"
        written = subprocess.run(
            [sys.executable, "-c", WRITE_LOG, str(self.log)],
            capture_output=True,
            text=True,
            env=env,
            timeout=WAIT,
        )
        assert written.returncode == 0, written.stderr
        self.naming = NamingProcess(options=("--channel", "EventChannel"))
        self.procs: list[subprocess.Popen[str]] = []
        self.player = self._popen(
            "-m",
            "miro_gen.cli.main",
            "log",
            "play",
            str(self.log),
            "--foxglove",
            "127.0.0.1:0",
            "--rate",
            "0.5",
            "--wait",
            "0",
        )
        self.player_err = Lines(self.player.stderr)
        port = self.player_err.wait_for(r"replay to Foxglove at ws://127\.0\.0\.1:(\d+)$")[1]
        self.url = f"ws://127.0.0.1:{port}"
        self.follower = self._popen(
            str(REPO / "tests" / "procs" / "clocked_publisher.py"), "--clock", "log", "0.05"
        )
        Lines(self.follower.stdout).wait_for("^READY$")
        self.listener = RunningServer(self.naming.endpoint, "test")
        self.ticks = Recorder(self.listener.server.resolve_channel("EventChannel"))
        self.ticks.set_subscriptions([("robot1", "Tick")])

    def _popen(self, *args: str) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [sys.executable, *args, "--naming", self.naming.endpoint, "-MNC", "robot1"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            stdin=subprocess.DEVNULL,
            env=service_env(),
        )
        self.procs.append(proc)
        return proc

    def stop(self) -> None:
        self.listener.stop()
        for proc in self.procs:
            if proc.poll() is None:
                proc.terminate()
        for proc in self.procs:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.naming.stop()


@pytest.fixture
def replay(tmp_path: Path) -> Iterator[Replay]:
    r = Replay(tmp_path)
    try:
        yield r
    finally:
        r.stop()
    said = r.player_err.all()
    assert not any("Traceback" in line for line in said), said


def test_a_seek_from_foxglove_plays_from_the_first_event_after_it(replay: Replay) -> None:
    seek = T0 + 250 * STEP + STEP // 2  # between events 250 and 251
    done = subprocess.run(
        [
            "node",
            str(FOXGLOVE / "client.mjs"),
            replay.url,
            json.dumps(
                [
                    {"op": "channels", "has": ["robot1/Pose"]},
                    {
                        "op": "seekPlay",
                        "topic": "robot1/Pose",
                        "seek": str(seek),
                        "speed": 2,
                        "count": 3,
                    },
                ]
            ),
        ],
        capture_output=True,
        text=True,
        timeout=WAIT,
        cwd=FOXGLOVE,
    )
    assert done.returncode == 0, done.stderr + done.stdout
    results = [json.loads(line) for line in done.stdout.splitlines()]
    paused = next(r["paused"] for r in results if "paused" in r)
    seeked = next(r["seeked"] for r in results if "seeked" in r)
    played = [r for r in results if "message" in r]
    assert paused["status"] == 1  # Paused
    assert seeked["didSeek"] and int(seeked["time"]) == seek and seeked["speed"] == 2
    assert [int(p["message"]["stamp"]) for p in played] == [251, 252, 253]
    assert [int(p["timestamp"]) for p in played] == [T0 + k * STEP for k in (251, 252, 253)]
    # A process on --clock log follows the seek: its ticks are stamped after it, in log time.
    eventually(lambda: any(seek / 1e9 <= e.stamp < seek / 1e9 + 60 for e in replay.ticks.events))
    assert played[0]["message"] == {
        "where": {"x": 251, "y": -251},
        "heading": 125.5,
        "frame": "log",
        "covariance": [],
        "drive_mode": 2,
        "stamp": "251",
    }
