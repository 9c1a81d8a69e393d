"""Miro's C++ services and Python services on one event channel, through its Notification door
(CosNotifyChannelAdmin, issue 27): a C++ supplier and a C++ consumer written as Miro's
StructuredPushSupplier and StructuredPushConsumer are (tests/corba/notify_peer.cc, built with
g++ against omniORB and its CosNotify stubs), and miro-gen's StructuredPushSupplier and
StructuredPushConsumer, in real processes.

Everything runs twice: with omniNames as the naming service (the channel hosted by a Python
server, bound in omniNames as `robot1/EventChannel`), and with `miro naming --iiop-endpoint`
alone (hosting the channel, answering CosNaming), where omniORB's `nameclt` lists the robot.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import Miro
import Miro__POA
import pytest
import zmq
from corba_peers import (
    CppPeer,
    OmniNames,
    build_notify_peer,
    notify_tools_missing,
    readline,
)
from loopback import eventually, free_port, service_env
from miro_cli import REPO

from miro_gen import Server
from miro_gen.transport.events import (
    KEEP_ALL,
    EventChannel,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)

pytestmark = [
    pytest.mark.skipif(bool(notify_tools_missing()), reason=f"needs {notify_tools_missing()}"),
    pytest.mark.timeout(300),
]

ROBOT = "robot1"
WAIT = 30.0  # seconds anything may take, at most (a loaded machine), before a test fails


@dataclass
class World:
    """A naming service and the process that hosts the channel `robot1/EventChannel`."""

    kind: str
    python_naming: list[str]  # what Python services are given
    cpp_naming: str  # NameService=... for the C++ peers
    host_log: Path  # what the channel's host logs
    host: subprocess.Popen[str]
    omninames: OmniNames | None = None

    def stop(self) -> None:
        if self.host.poll() is None:
            self.host.send_signal(signal.SIGTERM)
        try:
            self.host.wait(10)
        except subprocess.TimeoutExpired:
            self.host.kill()
            self.host.wait(10)
        if self.omninames is not None:
            self.omninames.stop()

    def log_says(self, text: str) -> bool:
        return text in self.host_log.read_text(errors="replace")


def _start(cmd: list[str], log: Path, ready: str) -> subprocess.Popen[str]:
    with open(log, "w") as err:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=err, text=True, env=service_env(), cwd=REPO
        )
    assert proc.stdout is not None
    while True:
        line = readline(proc.stdout, WAIT, cmd[3])
        if line.startswith(ready):
            return proc
        assert line or proc.poll() is None, log.read_text()


@pytest.fixture(scope="module", params=["miro-naming", "omninames"])
def world(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[World]:
    folder = tmp_path_factory.mktemp(request.param)
    log = folder / "host.log"
    python = [sys.executable, "-m", "miro_gen.cli.main"]
    if request.param == "miro-naming":
        zmq_port = free_port()
        iiop_port = free_port()
        while iiop_port == zmq_port:
            iiop_port = free_port()
        endpoint = f"tcp://127.0.0.1:{zmq_port}"
        host = _start(
            [*python, "naming", "--endpoint", endpoint, "--iiop-endpoint",
             f"127.0.0.1:{iiop_port}", "--channel", f"{ROBOT}/EventChannel", "--log-file",
             str(folder / "owners.log"), "-MLL", "6"],
            log, "event channel",
        )  # fmt: skip
        w = World(
            request.param,
            ["--naming", endpoint],
            f"corbaloc::127.0.0.1:{iiop_port}/NameService",
            log,
            host,
        )
    else:
        names = OmniNames()
        host = _start(
            [sys.executable, str(REPO / "tests/procs/channel_host.py"), "--naming", names.url,
             "-MNC", ROBOT, "-MLL", "6", "EventChannel"],
            log, "READY",
        )  # fmt: skip
        w = World(request.param, ["--naming", names.url], names.url, log, host, names)
    try:
        yield w
    finally:
        w.stop()


@pytest.fixture(scope="module")
def notify_bin() -> Path:
    return build_notify_peer()


class PythonSide:
    """A Python server on the robot, its reactor running in a thread, and the channel."""

    def __init__(self, world: World) -> None:
        self.server = Server(
            ["test", *world.python_naming, "-MNC", ROBOT, "--wait-naming", str(WAIT)],
            context=zmq.Context(),
        )
        self.channel: EventChannel = self.server.resolve_channel("EventChannel")
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.thread.join(10)


@pytest.fixture(scope="module")
def python(world: World) -> Iterator[PythonSide]:
    side = PythonSide(world)
    try:
        yield side
    finally:
        side.close()


class Collector(StructuredPushConsumer):
    """Keeps every event it receives."""

    def __init__(self, channel: EventChannel, subscriptions: list[tuple[str, str]]) -> None:
        super().__init__(channel, depth=KEEP_ALL)
        self.events: list[StructuredEvent] = []
        self.cond = threading.Condition()
        self.set_subscriptions(subscriptions)

    def push_structured_event(self, event: StructuredEvent) -> None:
        with self.cond:
            self.events.append(event)
            self.cond.notify_all()

    def wait(self, n: int) -> list[StructuredEvent]:
        with self.cond:
            assert self.cond.wait_for(lambda: len(self.events) >= n, WAIT), self.events
            return list(self.events)


def peer(binary: Path, world: World, mode: str, *args: str) -> CppPeer:
    return CppPeer(binary, mode, *args, naming=world.cpp_naming)


def expect(p: CppPeer, wanted: str) -> list[str]:
    """The lines of `p` up to the one starting with `wanted` (which must come)."""
    lines = []
    while True:
        line = p.readline(WAIT)
        lines.append(line)
        if line.startswith(wanted):
            return lines
        assert not line.startswith("FAIL"), lines


def send(p: CppPeer, line: str = "go") -> None:
    assert p.proc.stdin is not None
    p.proc.stdin.write(line + "\n")
    p.proc.stdin.flush()


def subscription_types(binary: Path, world: World) -> set[str]:
    """The channel's subscriptions as a C++ supplier sees them (obtain_subscription_types)."""
    status, out = run(binary, world, "subscriptions")
    assert status == 0 and "END" in out, out
    return {line[5:] for line in out.splitlines() if line.startswith("TYPE ")}


def run(binary: Path, world: World, *args: str) -> tuple[int, str]:
    done = subprocess.run(
        [str(binary), *args, "-ORBInitRef", f"NameService={world.cpp_naming}"],
        capture_output=True, text=True, timeout=WAIT, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    return done.returncode, done.stdout + done.stderr


def until_subscribed(binary: Path, world: World, wanted: str) -> None:
    """Wait until the C++ side sees `wanted` ("robot1 Gps") among the subscriptions."""
    eventually(
        lambda: wanted in subscription_types(binary, world),
        WAIT,
        lambda: f"{wanted} never subscribed",
    )


def gps_line(i: int) -> str:
    """What the C++ consumer prints for the Gps event number `i` of the C++ supplier."""
    return f"EVENT {ROBOT} Gps gps {1000 + i} {48 + i * 0.001:.6f} {9 + i * 0.001:.6f} " \
        f"{500.25 + i:.2f} 7 sats 2"  # fmt: skip


def scan_line(i: int) -> str:
    return f"EVENT {ROBOT} Laser scan {3000 + i} {i * 10},{i * 10 + 1},{i * 10 + 2}|-1"


# ---- C++ to Python ------------------------------------------------------------------------------


def test_cpp_events_reach_a_python_consumer_decoded(
    notify_bin: Path, world: World, python: PythonSide
) -> None:
    collector = Collector(python.channel, [(ROBOT, "*")])
    supplier = peer(notify_bin, world, "supply", "3")
    try:
        until_subscribed(notify_bin, world, f"{ROBOT} *")
        lines = expect(supplier, "READY")
        assert f"SUBSCRIBED {ROBOT} Gps 1" in lines and f"SUBSCRIBED {ROBOT} Laser 1" in lines
        send(supplier)
        expect(supplier, "SENT 6")
        events = collector.wait(6)
        gps = [e for e in events if e.type_name == "Gps"]
        scans = [e for e in events if e.type_name == "Laser"]
        assert [e.seq for e in gps] == [0, 1, 2] and [e.seq for e in scans] == [0, 1, 2]
        assert {e.domain_name for e in events} == {ROBOT}
        for i, e in enumerate(gps):
            g = e.payload
            assert isinstance(g, Miro.GpsDataIDL)
            assert (g.time.sec, g.time.usec, g.utcTime.sec) == (1000 + i, 500, 2000 + i)
            assert g.valid == (i % 2 == 0)
            assert g.quality == Miro.GpsFixQualityIDL.GPS_FIX_DGPS
            assert g.mode == Miro.GpsFixModeIDL.GPS_MODE_3D
            assert (g.latitude, g.longitude) == (48.0 + i * 0.001, 9.0 + i * 0.001)
            assert g.altitude == 500.25 + i and g.geoidSeparation == 47.5
            assert list(g.satellites) == [i, i + 1] and g.dgpsStation == 42
        for i, e in enumerate(scans):
            s = e.payload
            assert isinstance(s, Miro.RangeScanEventIDL)
            assert (s.time.sec, s.time.usec) == (3000 + i, 7)
            assert [list(group) for group in s.range] == [[i * 10, i * 10 + 1, i * 10 + 2], [-1]]
        assert collector.missed == 0
    finally:
        collector.close()
        supplier.kill()


# ---- Python to C++ ------------------------------------------------------------------------------


def test_python_events_reach_a_cpp_consumer_as_it_subscribed(
    notify_bin: Path, world: World, python: PythonSide
) -> None:
    consumer = peer(notify_bin, world, "consume", "3", f"{ROBOT}/Gps")
    supplier = StructuredPushSupplier(python.channel)
    elsewhere = StructuredPushSupplier(python.channel, domain_name="robot2")
    try:
        expect(consumer, "CONNECTED")
        eventually(  # the C++ subscription, through the door
            lambda: supplier.has_subscribers("Gps"),
            WAIT,
            lambda: "the C++ consumer's subscription never came",
        )
        assert not supplier.has_subscribers("Laser")
        assert not elsewhere.has_subscribers("Gps")
        for i in range(3):
            fix = Miro.GpsDataIDL(
                time=Miro.TimeIDL(1000 + i, 0), latitude=48.0 + i * 0.001,
                longitude=9.0 + i * 0.001, altitude=500.25 + i, satellitesUsed=7,
                satellites=[1, 2],
            )  # fmt: skip
            assert supplier.push("Gps", fix)
            assert not supplier.push("Laser", Miro.RangeScanEventIDL(Miro.TimeIDL(i, 0), [[1]]))
            assert not elsewhere.push("Gps", fix)
        lines = expect(consumer, "DONE")
        events = [line for line in lines if line.startswith("EVENT")]
        assert events == [gps_line(i) for i in range(3)], lines
    finally:
        consumer.kill()
        supplier.close()
        elsewhere.close()


def test_a_cpp_supplier_sees_the_python_consumers_subscriptions(
    notify_bin: Path, world: World, python: PythonSide
) -> None:
    supplier = peer(notify_bin, world, "supply", "1")
    collectors = []
    try:
        expect(supplier, "READY")
        collectors.append(Collector(python.channel, [(ROBOT, "Laser")]))
        expect(supplier, f"CHANGE + {ROBOT} Laser")  # subscription_change, pushed to it
        collectors.append(Collector(python.channel, [(ROBOT, "Odometry"), ("robot2", "*")]))
        until_subscribed(notify_bin, world, f"{ROBOT} Odometry")
        assert {f"{ROBOT} Laser", f"{ROBOT} Odometry", "robot2 *"} <= subscription_types(
            notify_bin, world
        )
        collectors.pop().close()
        eventually(
            lambda: f"{ROBOT} Odometry" not in subscription_types(notify_bin, world),
            WAIT,
            lambda: "the subscription outlived its consumer",
        )
    finally:
        for c in collectors:
            c.close()
        supplier.kill()


# ---- logs ---------------------------------------------------------------------------------------


def test_cpp_events_recorded_and_replayed_to_a_cpp_consumer(
    notify_bin: Path, world: World, python: PythonSide, tmp_path: Path
) -> None:
    log = tmp_path / "cpp.mcap"
    miro = [sys.executable, "-m", "miro_gen.cli.main", "log"]
    common = [*world.python_naming, "-MNC", ROBOT]
    recorder = subprocess.Popen(
        [*miro, "record", *common, "-o", str(log), "-n", "6", f"{ROBOT}/Gps", f"{ROBOT}/Laser"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=service_env(),
        cwd=REPO,
    )  # fmt: skip
    collector = Collector(python.channel, [(ROBOT, "*")])
    supplier = peer(notify_bin, world, "supply", "3")
    consumer = None
    try:
        until_subscribed(notify_bin, world, f"{ROBOT} Gps")  # the recorder
        until_subscribed(notify_bin, world, f"{ROBOT} Laser")
        expect(supplier, "READY")
        send(supplier)
        expect(supplier, "SENT 6")
        collector.wait(6)
        out, _ = recorder.communicate(timeout=WAIT)  # it stops at its sixth event
        assert recorder.returncode == 0, out
        info = subprocess.run(
            [*miro, "info", str(log)], capture_output=True, text=True, env=service_env(),
            cwd=REPO, timeout=WAIT,
        )  # fmt: skip
        assert f"{ROBOT}/Gps" in info.stdout and "Miro::GpsDataIDL" in info.stdout, info.stdout
        consumer = peer(notify_bin, world, "consume", "6", f"{ROBOT}/*")
        expect(consumer, "CONNECTED")
        until_subscribed(notify_bin, world, f"{ROBOT} *")
        played = subprocess.run(
            [*miro, "play", *common, "--wait", "0.5", "--rate", "100", str(log)],
            capture_output=True, text=True, env=service_env(), cwd=REPO, timeout=WAIT,
        )  # fmt: skip
        assert played.returncode == 0, played.stdout + played.stderr
        lines = expect(consumer, "DONE")
        events = [line for line in lines if line.startswith("EVENT")]
        assert [e for e in events if " Gps " in e] == [gps_line(i) for i in range(3)], lines
        assert [e for e in events if " Laser " in e] == [scan_line(i) for i in range(3)], lines
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate(timeout=10)
        collector.close()
        supplier.kill()
        if consumer is not None:
            consumer.kill()


# ---- failures -----------------------------------------------------------------------------------


def test_a_killed_cpp_consumer_stops_no_one(
    notify_bin: Path, world: World, python: PythonSide
) -> None:
    doomed = peer(notify_bin, world, "consume", "1000", f"{ROBOT}/Gps")
    survivor = peer(notify_bin, world, "consume", "1000", f"{ROBOT}/Gps")
    collector = Collector(python.channel, [(ROBOT, "Gps")])
    supplier = peer(notify_bin, world, "supply", "4")
    try:
        for p in (doomed, survivor):
            expect(p, "CONNECTED")
        until_subscribed(notify_bin, world, f"{ROBOT} Gps")
        expect(supplier, "READY")
        send(supplier)
        expect(supplier, "SENT 8")
        for p in (doomed, survivor):
            expect(p, "EVENT " + gps_line(3)[6:])
        doomed.proc.kill()
        doomed.proc.wait(10)
        for burst in (2, 3):
            send(supplier)
            expect(supplier, f"SENT {8 * burst}")  # the supplier is not held up either
        lines = expect(survivor, "EVENT " + gps_line(11)[6:])
        assert [line for line in lines if line.startswith("EVENT")] == [
            gps_line(i) for i in range(4, 12)
        ]
        assert [e.payload.time.sec for e in collector.wait(12)] == [1000 + i for i in range(12)]
        eventually(lambda: world.log_says("dropped its consumer"), WAIT, world.host_log.read_text)
    finally:
        for p in (doomed, survivor, supplier):
            p.kill()
        collector.close()


# ---- naming -------------------------------------------------------------------------------------


class Example(Miro__POA.Example):  # type: ignore[misc]
    def __init__(self) -> None:
        self.data = (0.0, 0.0)

    def setData(self, a: float, b: float) -> None:
        self.data = (a, b)

    def getData(self) -> tuple[float, float]:
        return self.data


def nameclt(world: World, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["nameclt", "-ORBInitRef", f"NameService={world.cpp_naming}", *args],
        capture_output=True, text=True, timeout=WAIT,
    )  # fmt: skip


def test_nameclt_lists_the_robot_that_miro_naming_alone_names(
    world: World, python: PythonSide
) -> None:
    if world.kind != "miro-naming":
        pytest.skip("omniNames lists what it holds itself")
    python.server.add_to_name_service(Example(), "Example")
    eventually(
        lambda: "Example" in nameclt(world, "list", ROBOT).stdout,
        WAIT,
        lambda: str(nameclt(world, "list", ROBOT)),
    )
    listed = nameclt(world, "list", ROBOT).stdout.split()
    assert "EventChannel" in listed and "Example" in listed
    root = nameclt(world, "list").stdout.split()
    assert f"{ROBOT}/" in root and "NotifyEventChannelFactory" in root
    channel_ior = nameclt(world, "resolve", f"{ROBOT}/EventChannel").stdout.strip()
    assert channel_ior.startswith("IOR:")
    # A name of the Python service is its own: a C++ client of the same user (another service)
    # can neither replace nor remove it.
    refused = nameclt(world, "-advanced", "rebind", f"{ROBOT}/Example", channel_ior)
    assert refused.returncode != 0 or "NO_PERMISSION" in refused.stdout + refused.stderr
    assert nameclt(world, "unbind", f"{ROBOT}/Example").returncode != 0
    assert "Example" in nameclt(world, "list", ROBOT).stdout
    # What a C++ client binds, a Python client finds, and the reverse.
    assert nameclt(world, "bind_new_context", "robot9").returncode == 0
    bound = nameclt(world, "bind", "robot9/Channel", channel_ior)
    assert bound.returncode == 0, bound.stdout + bound.stderr
    found = python.server.resolve_channel("robot9/Channel")
    assert found.consumer_endpoint == python.channel.consumer_endpoint
    assert nameclt(world, "bind", "robot9/Channel", channel_ior).returncode != 0  # AlreadyBound
    assert nameclt(world, "unbind", "robot9/Channel").returncode == 0
    assert nameclt(world, "remove_context", "robot9").returncode == 0
    assert "robot9" not in nameclt(world, "list").stdout


def test_the_channels_host_logged_no_defect(world: World) -> None:
    """Everything above left no traceback in the log of the process hosting the channel."""
    text = world.host_log.read_text(errors="replace")
    assert "Traceback" not in text, text


def test_a_python_client_calls_a_cpp_server_that_miro_naming_names(
    peer_bin: Path, peer_gen: Any, world: World, python: PythonSide
) -> None:
    """One naming service for both worlds: a C++ server binds its object through CosNaming
    (as Miro's Server does), a Python client of the ZeroMQ naming service finds and calls it."""
    if world.kind != "miro-naming":
        pytest.skip("with omniNames, Python services use CosNaming already (test_corba_interop)")
    server = CppPeer(peer_bin, "server", f"{ROBOT}/Echo", naming=world.cpp_naming)
    try:
        server.ready()
        echo = python.server.resolve_name("Echo", peer_gen.Peer.Echo)  # in -MNC robot1
        assert echo.echo_text("from python") == "from python"
        assert list(echo.echo_longs([1, 2, 3])) == [1, 2, 3]
    finally:
        server.kill()
