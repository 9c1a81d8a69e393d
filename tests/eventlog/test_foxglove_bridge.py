"""`miro foxglove` seen from Foxglove's own libraries: a running robot in Foxglove.

A robot (tests/procs/fox_robot.py: FoxTest::Scan and FoxTest::Pose events, the manual's
Miro::Example as ExampleA, Miro::GpsParameters live) runs beside `miro foxglove`, which has no
generated FoxTest of its own (it compiles what the robot's service says). tests/foxglove/
client.mjs is the Foxglove side: @foxglove/ws-protocol's client over `ws`, speaking the
subprotocol foxglove.sdk.v1, decoding with @foxglove/omgidl-parser and
@foxglove/omgidl-serialization. It subscribes and decodes what the supplier pushed, calls the
object's operations, gets, sets and subscribes to parameters, and publishes events that the
robot's consumer receives. Needs node and the npm packages of tests/foxglove (`.ci/run`
installs them with `npm ci`).
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from loopback import NamingProcess, run_miro, service_env
from miro_cli import REPO, run_miro_idl

FOXGLOVE = REPO / "tests" / "foxglove"
PROCS = REPO / "tests" / "procs"
WAIT = 60  # seconds: only against hangs
PARAM = "robot1/fox_robot/Gps/Gps.WaitTimeout"


def _skip_reason() -> str | None:
    try:
        import foxglove  # noqa: F401
    except ImportError:
        return "foxglove-sdk is not installed (the foxglove extra)"
    if shutil.which("node") is None:
        return "node is not installed (Foxglove's libraries are JavaScript)"
    for package in ("@foxglove/ws-protocol", "@foxglove/omgidl-serialization", "ws"):
        if not (FOXGLOVE / "node_modules" / package).is_dir():
            return f"{package} is not installed: run `npm ci` in tests/foxglove (.ci/run does)"
    return None


pytestmark = pytest.mark.skipif(_skip_reason() is not None, reason=str(_skip_reason()))


class Lines:
    """The lines a process writes to `stream`, read by a thread into a queue (`wait_for`
    takes them from it) and kept (`all`)."""

    def __init__(self, stream: Any) -> None:
        self.queue: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self._read_all: list[str] = []
        self._reader = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._reader.start()

    def _read(self, stream: Any) -> None:
        for line in stream:
            self._read_all.append(line.rstrip("\n"))
            self.queue.put(line.rstrip("\n"))

    def so_far(self) -> list[str]:
        """The lines read so far."""
        return list(self._read_all)

    def all(self) -> list[str]:
        """Every line the process wrote, once it has ended (its stream read to the end), not
        only those a test waited for: what a process said as it stopped is checked too."""
        self._reader.join(WAIT)
        return list(self._read_all)

    def wait_for(self, pattern: str) -> re.Match[str]:
        while True:
            try:
                line = self.queue.get(timeout=WAIT)
            except queue.Empty:
                raise AssertionError(f"no line matching {pattern!r}: {self.seen}") from None
            self.seen.append(line)
            found = re.search(pattern, line)
            if found:
                return found


class Robot:
    """The robot's processes and the bridge's address."""

    def __init__(self, folder: Path) -> None:
        generated = folder / "gen"
        compiled = run_miro_idl("-o", str(generated), str(FOXGLOVE / "FoxTest.idl"))
        assert compiled.returncode == 0, compiled.stderr
        self.env = service_env(MIRO_CACHE=str(folder / "cache"))
        self.robot_env = dict(self.env)
        self.robot_env["PYTHONPATH"] = os.pathsep.join([str(generated), self.env["PYTHONPATH"]])
        self.naming = NamingProcess(options=("--channel", "EventChannel"))
        self.procs: list[subprocess.Popen[str]] = []
        self.robot, self.robot_out = self.start_robot("robot1")
        # (-MLL 6: it says which topics it advertises and withdraws)
        self.bridge, self.bridge_err, self.url = self.start_bridge("-MLL", "6")

    def start_bridge(
        self, *options: str, context: str = "bridge"
    ) -> tuple[subprocess.Popen[str], Lines, str]:
        """`miro foxglove` on a free port: the process, its standard error, its URL."""
        bridge = self._popen(
            [
                sys.executable,
                "-m",
                "miro_gen.cli.main",
                "foxglove",
                "--naming",
                self.naming.endpoint,
                "-MNC",
                context,
                "--port",
                "0",
                "--refresh",
                "0.2",
                *options,
            ],
            self.env,
        )
        err = Lines(bridge.stderr)
        port = err.wait_for(r"serving EventChannel at ws://127\.0\.0\.1:(\d+) ")[1]
        return bridge, err, f"ws://127.0.0.1:{port}"

    def _popen(self, argv: list[str], env: dict[str, str]) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        )
        self.procs.append(proc)
        return proc

    def start_robot(self, context: str) -> tuple[subprocess.Popen[str], Lines]:
        proc = self._popen(
            [
                sys.executable,
                str(PROCS / "fox_robot.py"),
                "--naming",
                self.naming.endpoint,
                "-MNC",
                context,
            ],
            self.robot_env,
        )
        out = Lines(proc.stdout)
        out.wait_for("^READY$")
        return proc, out

    def client(self, *steps: dict[str, Any], url: str | None = None) -> list[dict[str, Any]]:
        """Run client.mjs with `steps` (on the bridge at `url`, default the first); its
        results, the server's info left out."""
        done = subprocess.run(
            ["node", str(FOXGLOVE / "client.mjs"), url or self.url, json.dumps(list(steps))],
            capture_output=True,
            text=True,
            timeout=WAIT,
            cwd=FOXGLOVE,
        )
        assert done.returncode == 0, done.stderr + done.stdout
        results = [json.loads(line) for line in done.stdout.splitlines()]
        assert results[-1] == {"done": True}
        return results[1:-1]

    def miro(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *args, "--naming", self.naming.endpoint],
            capture_output=True,
            text=True,
            env=self.env,
            timeout=WAIT,
        )

    def stop(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in self.procs:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.naming.stop()


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Robot]:
    r = Robot(tmp_path_factory.mktemp("foxrobot"))
    try:
        yield r
    finally:
        r.stop()
    said = r.bridge_err.all()
    assert r.bridge.returncode == 0, said
    assert not any("Traceback" in line for line in said), said


def sent_scans(robot: Robot) -> list[dict[str, Any]]:
    """fox_supplier.scans() as Foxglove's MessageReader decodes them (client.mjs: a long long
    as a string)."""
    env = dict(robot.robot_env)
    env["PYTHONPATH"] = os.pathsep.join([str(PROCS), env["PYTHONPATH"]])
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            "import json, fox_supplier\n"
            "print(json.dumps([fox_supplier.plain(s) for s in fox_supplier.scans()]))",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=WAIT,
    )
    assert done.returncode == 0, done.stderr
    scans: list[dict[str, Any]] = json.loads(done.stdout)
    for s in scans:
        s["big"] = str(s["big"])
    return scans


def test_a_client_decodes_the_supplied_events_with_the_advertised_omgidl_schema(
    robot: Robot,
) -> None:
    got = robot.client(
        {"op": "receive", "topic": "robot1/Scan", "count": 18},
        {"op": "receive", "topic": "robot1/Pose", "count": 3},
    )
    scans = [g for g in got if g["topic"] == "robot1/Scan"]
    poses = [g for g in got if g["topic"] == "robot1/Pose"]
    assert {g["schema"] for g in scans} == {"FoxTest::Scan"}
    sent = sent_scans(robot)
    by_id = {s["id"]: s for s in sent}
    for g in scans:  # every message is one the supplier pushed, member for member
        assert g["message"] == by_id[g["message"]["id"]]
    assert {g["message"]["id"] for g in scans} == set(by_id)  # 18 in a row: each of the six
    n = [int(p["message"]["stamp"]) for p in poses]
    assert n == sorted(n) and len(set(n)) == 3
    for p, k in zip(poses, n, strict=True):
        assert p["message"] == {
            "where": {"x": k, "y": -k},
            "heading": 0.5 * k,
            "frame": "map",
            "covariance": [0.1] * 3,
            "drive_mode": 1,
            "stamp": str(k),
        }


def test_services_call_the_objects_and_say_failures(robot: Robot) -> None:
    got = robot.client(
        {"op": "call", "service": "robot1/ExampleA/setData", "request": {"a": 1.5, "b": 2}},
        {"op": "call", "service": "robot1/ExampleA/getData", "request": {}},
        {"op": "call", "service": "robot1/ExampleA/setData", "request": {"a": "x", "b": 1}},
        {"op": "call", "service": "robot1/ExampleA/setData", "request": {"a": 1}},
        {"op": "call", "service": "robot1/ExampleA/getData", "request": {}},
    )
    assert got[0] == {"service": "robot1/ExampleA/setData", "response": {}}
    assert got[1]["response"] == {"return": {"a": 2.5, "b": 3.0}}  # getData steps them
    assert "a" in got[2]["failure"] and "response" not in got[2]
    assert "b missing" in got[3]["failure"]
    assert got[4]["response"] == {"return": {"a": 3.5, "b": 4.0}}  # the failures changed nothing


def test_a_parameter_set_is_what_the_service_then_reports(robot: Robot) -> None:
    got = robot.client(
        {"op": "get", "names": [PARAM]},
        {"op": "set", "params": [{"name": PARAM, "value": "0, 5"}]},
        {"op": "set", "params": [{"name": PARAM, "value": "soon"}]},
        {"op": "status"},
    )
    assert got[0] == {"get": [{"name": PARAM, "value": "5, 0"}]}
    assert got[1] == {"set": [{"name": PARAM, "value": "0, 5"}]}
    assert got[2] == {"set": [{"name": PARAM, "value": "0, 5"}]}  # refused: all or nothing
    assert "Gps.WaitTimeout" in got[3]["status"] and "soon" in got[3]["status"]
    shown = robot.miro("param", "get", "robot1/fox_robot", "Gps.WaitTimeout")
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout == "0, 5\n"  # the service itself reports the value set in Foxglove


def test_a_subscribed_parameter_is_sent_when_the_service_changes_it(robot: Robot) -> None:
    name = "robot1/fox_robot/Gps/Gps.EventName"
    steps = [{"op": "subscribeParams", "names": [name], "count": 2}]
    watcher = subprocess.Popen(
        ["node", str(FOXGLOVE / "client.mjs"), robot.url, json.dumps(steps)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=FOXGLOVE,
    )
    try:
        out = Lines(watcher.stdout)
        first = json.loads(out.wait_for("update").string)
        assert first == {"update": [{"name": name, "value": "Gps"}]}
        done = robot.miro("param", "set", "robot1/fox_robot", "Gps.EventName", "Fix")
        assert done.returncode == 0, done.stderr
        second = json.loads(out.wait_for("update").string)
        assert second == {"update": [{"name": name, "value": "Fix"}]}
        assert watcher.wait(WAIT) == 0
    finally:
        if watcher.poll() is None:
            watcher.kill()
            watcher.wait()


def test_what_a_client_publishes_a_miro_consumer_receives(robot: Robot) -> None:
    messages = [
        {
            "where": {"x": 1.0, "y": 2.0},
            "heading": 0.5,
            "frame": "odom",
            "covariance": [1.0, 2.0],
            "drive_mode": 2,
            "stamp": k,
        }
        for k in (101, 102, 103)
    ]
    got = robot.client(
        {"op": "publish", "topic": "robot1/Echo", "like": "robot1/Pose", "messages": messages}
    )
    assert got == [{"published": 3}]
    echoed = [json.loads(robot.robot_out.wait_for('^{"echo"').string)["echo"] for _ in messages]
    assert echoed == messages


def test_topics_come_and_go_with_their_suppliers(robot: Robot) -> None:
    other, _ = robot.start_robot("robot2")
    got = robot.client({"op": "channels", "has": ["robot2/Scan", "robot2/Pose"]})
    assert {"robot1/Scan", "robot1/Pose", "robot2/Scan", "robot2/Pose"} <= set(got[0]["channels"])
    other.send_signal(signal.SIGINT)
    other.wait(WAIT)
    # (A new client hears the advertised topics a moment after the server's info: "lacks"
    # alone held before that, on an empty list. robot1's are waited for, and the bridge
    # never withdrew them meanwhile.)
    got = robot.client(
        {
            "op": "channels",
            "has": ["robot1/Scan", "robot1/Pose"],
            "lacks": ["robot2/Scan", "robot2/Pose"],
        }
    )
    assert {"robot1/Scan", "robot1/Pose"} <= set(got[0]["channels"])
    assert not {"robot2/Scan", "robot2/Pose"} & set(got[0]["channels"])
    said = robot.bridge_err.so_far()
    assert not [line for line in said if "robot1/" in line and "no longer offered" in line], said
    assert [line for line in said if "robot2/Scan is no longer offered" in line], said


def test_beyond_loopback_it_takes_tls_or_insecure() -> None:
    done = run_miro("foxglove", "--address", "0.0.0.0", "--naming", "tcp://127.0.0.1:9")
    assert done.returncode == 2
    assert "not loopback" in done.stderr and "--insecure" in done.stderr
    assert "Traceback" not in done.stderr
    done = run_miro("foxglove", "--tls-cert", "/nonexistent.pem", "--tls-key", "/x.pem")
    assert done.returncode == 2 and "/nonexistent.pem" in done.stderr


def test_a_client_of_the_older_subprotocol_alone_is_refused_at_the_handshake(
    robot: Robot,
) -> None:
    """What docs/FOXGLOVE.md says of older apps: foxglove.websocket.v1 alone gets HTTP 400."""
    script = (
        'import WebSocket from "ws";\n'
        "const ws = new WebSocket(process.argv[1], [process.argv[2]]);\n"
        'ws.on("open", () => { console.log("open " + ws.protocol); ws.close(); });\n'
        'ws.on("unexpected-response", (_req, res) => { console.log("http " + res.statusCode);'
        " process.exit(0); });\n"
        'ws.on("error", (e) => { console.log("error " + e.message); });\n'
    )

    def handshake(subprotocol: str) -> str:
        done = subprocess.run(
            ["node", "--input-type=module", "-e", script, robot.url, subprotocol],
            capture_output=True,
            text=True,
            timeout=WAIT,
            cwd=FOXGLOVE,
        )
        return done.stdout.strip()

    assert handshake("foxglove.websocket.v1") == "http 400"
    assert handshake("foxglove.sdk.v1") == "open foxglove.sdk.v1"


def test_a_port_in_use_is_said_in_one_line(robot: Robot) -> None:
    port = robot.url.rsplit(":", 1)[1]
    done = robot.miro("foxglove", "--port", port, "-MNC", "bridge3")
    assert done.returncode == 1, done.stderr
    assert f"cannot serve on 127.0.0.1:{port}" in done.stderr
    assert "Traceback" not in done.stderr
