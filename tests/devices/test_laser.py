"""The laser scanner driver (services/laser) as a process, against the simulated scanner on a
pseudo-terminal and on a TCP port: streamed scans (MD) and polled ones (GD), in pieces, with
corrupt, truncated and out-of-order frames, a scanner that disappears and returns; every good scan
arrives as an event with the scene's ranges, the bad frames are counted and dropped, and the
polled interface answers."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
from device_rig import Driver
from loopback import NamingProcess, Recorder, RunningServer, eventually

from miro_gen import Client
from miro_gen.devices.scip import URG_04LX, UTM_30LX, Geometry
from miro_gen.sim.scip import Faults, PtyLink, RecordedScene, ScipDevice, ScipServer, TcpLink

RS = Miro.RangeSensor


def scene(geometry: Geometry, n: int = 7) -> RecordedScene:
    """`n` scans that differ everywhere, with error codes (below DMIN) and far readings."""
    steps = geometry.amax - geometry.amin + 1
    scans = []
    for k in range(n):
        scan = [300 + (37 * i + 101 * k) % 3500 for i in range(steps)]
        scan[10 + k] = 7  # an error code
        scans.append(scan)
    return RecordedScene(scans)


def expected(recorded: RecordedScene, geometry: Geometry) -> list[list[int]]:
    """What the driver publishes for each recorded scan (cluster 1, every step)."""

    def miro(v: int) -> int:
        if v < geometry.dmin:
            return RS.INVALID_RANGE
        return RS.HORIZON_RANGE if v > geometry.dmax else v

    return [[miro(v) for v in scan] for scan in recorded.scans]


class LaserRig:
    """A naming service, the simulated scanner (on a pseudo-terminal, or TCP with `tcp`), the
    driver, a consumer of its scans and a RangeSensor stub."""

    def __init__(
        self,
        tmp: Path,
        geometry: Geometry = URG_04LX,
        *,
        tcp: bool = False,
        faults: Faults | None = None,
        split: int = 0,
        **parameters: object,
    ) -> None:
        self.geometry = geometry
        self.scene = scene(geometry)
        self.device = ScipDevice(geometry, self.scene, faults=faults)
        self.link: PtyLink | TcpLink = TcpLink(0) if tcp else PtyLink(tmp / "laser0")
        self.sim = ScipServer(self.device, self.link, split=split, seed=7)
        self.thread = self.sim.start()
        self.naming = NamingProcess()
        self.driver = Driver(
            "laser", "Laser", self.naming.endpoint, tmp / "laser.log",
            Device=self.link.path, WaitTimeout="2, 0", **parameters,
        )  # fmt: skip
        self.gui = RunningServer(self.naming.endpoint, "gui")
        self.events = Recorder(self.gui.server.resolve_channel("rover/EventChannel"))
        self.events.set_subscriptions([("rover", "Laser")])
        self.client = Client(["t", "--naming", self.naming.endpoint])
        self.laser = self.client.resolve_name("rover/Laser", Miro.RangeSensor)
        eventually(lambda: self.driver.logged("someone subscribes") == 1)

    def scans(self) -> list[list[int]]:
        return [e.payload.range[0].tolist() for e in self.events.events]  # type: ignore[attr-defined]

    def close(self) -> str:
        try:
            return self.driver.stop(self.events) if self.driver.proc.poll() is None else ""
        finally:
            self.driver.kill()
            self.client.close()
            self.gui.stop()
            self.sim.stop()
            self.thread.join(5)
            self.link.close()
            self.naming.stop()


def settled(rig: LaserRig, quiet: float = 0.6) -> None:
    """Wait until no scan has arrived for `quiet` seconds."""
    count, since = -1, time.monotonic()
    while time.monotonic() - since < quiet:
        if len(rig.events.events) != count:
            count, since = len(rig.events.events), time.monotonic()
        time.sleep(0.05)


@pytest.fixture
def rigs(tmp_path: Path) -> Iterator[list[LaserRig]]:
    made: list[LaserRig] = []
    yield made
    for rig in made:
        rig.close()


def test_streamed_scans_in_pieces_with_bad_frames(tmp_path: Path, rigs: list[LaserRig]) -> None:
    faults = Faults(corrupt=7, truncate=11, repeat=13)
    rig = LaserRig(tmp_path, faults=faults, split=97)
    rigs.append(rig)
    eventually(lambda: len(rig.events.events) >= 1, 60)
    eventually(lambda: rig.device.scans >= 40, 30)
    rig.sim.pause(True)  # the device stops streaming, as if unplugged
    time.sleep(0.2)
    sent, scans = dict(faults.sent), rig.device.scans
    good = scans - sent["corrupt"] - sent["truncate"]
    eventually(lambda: len(rig.events.events) >= good, 30)  # the driver has read them all
    settled(rig)  # (and sent no more)
    summary = rig.close()
    # A last frame cut short waits in the driver for the rest, which never comes.
    waiting = scans % faults.truncate == 0 and scans % faults.corrupt != 0
    assert f"laser: {good} scans, {good} published" in summary, (summary, sent, scans)
    assert f"dropped {sent['corrupt']} with a bad checksum" in summary, summary
    assert f"{sent['truncate'] - waiting} truncated, {sent['repeat']} out of order" in summary
    assert rig.events.missed == 0 and len(rig.events.events) == good
    wanted = expected(rig.scene, rig.geometry)
    assert all(scan in wanted for scan in rig.scans())
    assert len({tuple(s) for s in rig.scans()}) > 1


def test_polled_scans_over_tcp_and_the_polled_interface(
    tmp_path: Path, rigs: list[LaserRig]
) -> None:
    rig = LaserRig(
        tmp_path, UTM_30LX, tcp=True, Continuous="false", Encoding=2, Cluster=3,
        FirstStep=100, LastStep=980, Height=450, Alpha=10,
    )  # fmt: skip
    rigs.append(rig)
    laser = rig.laser
    description = laser.getScanDescription()
    assert description.scanType == RS.FULL and description.eventName == "Laser"
    [group] = description.group
    assert len(group.sensor) == 294  # steps 100 to 980 in clusters of 3
    assert (group.description.minRange, group.description.maxRange) == (23, 60000)
    assert math.isclose(group.description.focus, 3 * 2 * math.pi / 1440)
    first, last = group.sensor[0], group.sensor[-1]
    assert first.height == 450 and math.isclose(first.alpha, math.radians(10))
    assert math.isclose(first.beta, (101 - 540) * 2 * math.pi / 1440)  # the cluster's middle
    assert math.isclose(last.beta, (979.5 - 540) * 2 * math.pi / 1440)
    scan = laser.getWaitFullScan()
    values = scan.range[0].tolist()
    assert len(values) == 294
    # Two characters a reading: the scene's, clipped to 4095 mm, the nearest of each cluster.
    steps = [s[100:981] for s in rig.scene.scans]
    clustered = [[min(min(s[i : i + 3]), 4095) for i in range(0, len(s), 3)] for s in steps]
    assert [RS.INVALID_RANGE if v < 23 else v for v in clustered[0]] in [
        [RS.INVALID_RANGE if v < 23 else v for v in c] for c in clustered
    ]
    assert any(values == [RS.INVALID_RANGE if v < 23 else v for v in c] for c in clustered)
    assert laser.getGroup(0).range and laser.getWaitGroup(0).group == 0
    with pytest.raises(Miro.EOutOfBounds):
        laser.getGroup(1)
    eventually(lambda: len(rig.events.events) >= 5)
    summary = rig.close()
    assert "0 with a bad checksum, 0 truncated, 0 out of order" in summary, summary


@pytest.mark.parametrize("tcp", [False, True], ids=["pty", "tcp"])
def test_a_scanner_that_disappears_and_returns(
    tmp_path: Path, rigs: list[LaserRig], tcp: bool
) -> None:
    rig = LaserRig(tmp_path, tcp=tcp)
    rigs.append(rig)
    eventually(lambda: len(rig.events.events) >= 2, 60)
    rig.sim.pause(True)
    if isinstance(rig.link, PtyLink):
        rig.link.vanish()
    else:  # the scanner's network goes: its connection is reset, it listens again later
        port = rig.link.port
        rig.link.close()
    eventually(lambda: rig.driver.logged("scanner lost") == 1, 60)
    with pytest.raises(Miro.ETimeOut):
        rig.laser.getWaitFullScan()
    if isinstance(rig.link, PtyLink):
        rig.link.appear()
    else:
        rig.link = TcpLink(port)
        rig.sim.link = rig.link
    rig.sim.pause(False)
    eventually(lambda: rig.driver.logged("scanner connected") == 2, 20)
    before = len(rig.events.events)
    eventually(lambda: len(rig.events.events) >= before + 3, 60)
    assert rig.laser.getWaitFullScan().range[0].tolist() in expected(rig.scene, rig.geometry)
