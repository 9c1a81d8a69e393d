"""The laser scanner driver: a Hokuyo scanner speaking SCIP 2.0 (URG-04LX, UTM-30LX, UST...)
on a serial line, USB or Ethernet, in the manual's Publish Server and Reactor shape (§6.2).

    python services/laser [-MCF robot.xml] [--device PATH|HOST:PORT] [common options]
    miro run laser [...]                  (the same, from an installed miro-gen)
    miro sim scip --link /tmp/laser0 &  python services/laser --device /tmp/laser0

It serves Miro::RangeSensor (bound as "Laser"): `getScanDescription()` (one group, a sensor per
reading, filled from the scanner's own PP parameters and the mounting position),
`getFullScan()` / `getWaitFullScan()` (the latest scan, the next one) and `getGroup(0)` /
`getWaitGroup(0)`; and it publishes every scan as a RangeScanEventIDL event ("Laser"), distances
in millimetres, RangeSensor::INVALID_RANGE where the scanner reports an error code (below its
minimum range), RangeSensor::HORIZON_RANGE beyond its maximum. Parameters:
services/laser/LaserParameters.xml, section "Laser", category "Laser".

The pieces (docs/DEVICES.md walks through them):
- Connection: `TtyConnection` (a serial port, any pyserial URL) or `SockConnection` (HOST:PORT),
  reopened when the scanner comes back;
- EventHandler: `DevEventHandler` with a `LineFramer` cutting responses at their empty line;
- Consumer: `ScipConsumer`, the protocol's state: on connection it stops any stream (QT), reads
  VV, PP and II, then asks for scans (MD, or GD after GD); each response is checked
  (miro_gen.devices.scip) and matched with what was asked; bad frames (a wrong checksum, cut
  short, an answer to nothing asked, a scan older than the last) are counted and dropped;
- Implementation: `LaserImpl`, the runtime's `Implementation` base for the polled interface
  and the events.
A reactor timer watches the scanner: silent for a second (or ten rotations), it is asked again
from the start. On exit the driver prints what it received and what it dropped.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import threading
import time
from array import array
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro
import Miro__POA
from Miro.LaserParameters import LaserParameters
from miro_gen import (
    Implementation,
    StructuredPushSupplier,
    log,
    nonblocking,
)
from miro_gen.devices import (
    Connection,
    DevConsumer,
    DevEventHandler,
    DevMessage,
    LineFramer,
    SockConnection,
    SubscriberNotice,
    TtyConnection,
    startup,
)
from miro_gen.devices.connection import DeviceUnavailable
from miro_gen.devices.scip import (
    Geometry,
    Response,
    ScanCommand,
    ScipError,
    decode_scan,
    parse_info,
    split_response,
)
from miro_gen.transport.reactor import Reactor

_log = log.logger("Laser")

RS = Miro.RangeSensor
REPLY_TIMEOUT = 1.0  # seconds a command may go unanswered
MAX_FRAME = 1 << 16  # bytes: the longest scan (UXM-30LX: 2161 steps) is under 8 KiB


def build_description(
    params: LaserParameters, geometry: Geometry, command: ScanCommand
) -> Miro.ScanDescriptionIDL:
    """One group of `command.values` sensors: each reading's direction from the device's
    geometry (the middle step of its cluster), the mounting position from the parameters."""
    step = 2 * math.pi / geometry.ares
    sensors = []
    for i in range(command.values):
        first = command.start + i * command.cluster
        middle = (first + min(first + command.cluster - 1, command.end)) / 2
        sensors.append(
            Miro.SensorPositionIDL(
                height=params.height,
                distance=params.distance,
                alpha=params.alpha,
                beta=params.beta + geometry.angle(middle),
                gamma=0.0,
                masked=False,
            )
        )
    group = Miro.SensorGroupIDL(
        Miro.SensorDescriptionIDL(geometry.dmin, geometry.dmax, step * command.cluster), sensors
    )
    return Miro.ScanDescriptionIDL(RS.FULL, params.eventName, [group])


class LaserImpl(Miro__POA.RangeSensor, Implementation[Miro.RangeScanEventIDL]):
    """Miro::RangeSensor for one scanner: one group, the whole scan."""

    def __init__(self, supplier: StructuredPushSupplier | None, params: LaserParameters) -> None:
        Implementation.__init__(
            self,
            supplier,
            params.eventName,
            initial=Miro.RangeScanEventIDL(),
            timeout=params.waitTimeout.total_seconds(),
        )
        self.event_name = params.eventName
        self._description: Miro.ScanDescriptionIDL | None = None
        self._described = threading.Event()

    def describe(self, description: Miro.ScanDescriptionIDL) -> None:
        self._description = description
        self._described.set()

    def getScanDescription(self) -> Miro.ScanDescriptionIDL:
        """The layout, once the scanner has told its geometry (waits for it up to the timeout;
        before that, a description without groups)."""
        self._described.wait(self.timeout)
        return self._description or Miro.ScanDescriptionIDL(RS.FULL, self.event_name, [])

    @nonblocking
    def getFullScan(self) -> Miro.RangeScanEventIDL:
        return self.latest()

    def getWaitFullScan(self) -> Miro.RangeScanEventIDL:
        return self.wait_next(Miro.ETimeOut)

    @nonblocking
    def getGroup(self, id: int) -> Miro.RangeGroupEventIDL:
        return self._group(id, self.latest())

    def getWaitGroup(self, id: int) -> Miro.RangeGroupEventIDL:
        self._group(id, Miro.RangeScanEventIDL())  # check the id before waiting
        return self._group(id, self.wait_next(Miro.ETimeOut))

    @staticmethod
    def _group(id: int, scan: Miro.RangeScanEventIDL) -> Miro.RangeGroupEventIDL:
        if id != 0:
            raise Miro.EOutOfBounds(what=f"group {id}: a laser scanner has one group, 0")
        return Miro.RangeGroupEventIDL(scan.time, 0, scan.range[0] if scan.range else array("i"))


def to_time(seconds: float) -> Miro.TimeIDL:
    sec = math.floor(seconds)
    return Miro.TimeIDL(sec, min(999_999, round((seconds - sec) * 1e6)))


class ScipConsumer(DevConsumer):
    """SCIP responses in, scans out to the Implementation; asks the scanner for what it needs."""

    def __init__(self, impl: LaserImpl, params: LaserParameters) -> None:
        self.impl = impl
        self.params = params
        self.connection: Connection | None = None
        self.geometry: Geometry | None = None
        self.scan: ScanCommand | None = None  # what is asked for, once the geometry is known
        self.counts = dict.fromkeys(
            ("scans", "checksum", "truncated", "out of order", "malformed", "errors", "restarts"),
            0,
        )
        self._asked: list[bytes] = []  # commands sent, their answers still to come, in order
        self._streaming = False
        self._last_stamp: int | None = None
        self._last_input = time.monotonic()
        self.subscribers = SubscriberNotice(impl.supplier, impl.type_name, "scans")

    # ---- what the scanner is asked --------------------------------------------------------------

    def connection_changed(self, connected: bool) -> None:
        _log.notice("scanner %s", "connected" if connected else "lost")
        self._asked, self._streaming, self._last_stamp = [], False, None
        if connected:
            self._start()

    def _start(self) -> None:
        """From the beginning: stop a stream left running, then who are you, what can you do."""
        self._asked, self._streaming, self._last_stamp = [], False, None
        self._last_input = time.monotonic()
        for command in (b"SCIP2.0", b"QT", b"VV", b"PP", b"II"):
            self._send(command)

    def _send(self, command: bytes) -> None:
        assert self.connection is not None
        self._asked.append(command)
        try:
            self.connection.write_message(command + b"\n")
        except DeviceUnavailable as e:
            _log.warning("cannot send %s: %s", command.decode(), e)

    def handle_timeout(self, _arg: object) -> None:
        """The watchdog (reactor timer): a scanner that stopped answering is asked again."""
        self.subscribers.check()
        if self.connection is None or not self.connection.connected:
            return
        period = self.geometry.period * (self.params.skip + 1) if self.geometry else 0.1
        limit = max(REPLY_TIMEOUT, 10 * period) if self._streaming else REPLY_TIMEOUT
        if (self._asked or self._streaming) and time.monotonic() - self._last_input > limit:
            self.counts["restarts"] += 1
            _log.warning("the scanner has said nothing for %.1f s: starting again", limit)
            self._start()

    # ---- what it answers ------------------------------------------------------------------------

    def handle_message(self, message: DevMessage) -> None:
        self._last_input = time.monotonic()
        frame = self._resynchronised(message.data)
        try:
            response = split_response(frame)
        except ScipError as e:
            self._drop(e.kind, str(e))
            return
        if self._asked and response.echo == self._asked[0]:
            self._answer(self._asked.pop(0), response, message.stamp)
        elif self._asked[:1] == [b"QT"]:
            _log.debug("before QT's answer, dropped %r", response.echo[:20])  # a stream's end
        elif self._is_scan(response.echo):
            self._scan(response, message.stamp)
        else:
            self._drop("out of order", f"an answer to nothing asked: {response.echo[:20]!r}")

    def _resynchronised(self, frame: bytes) -> bytes:
        """A frame cut short runs into the next one, maybe in the middle of a line: keep the
        last response that starts inside it (an expected echo, a status line), drop the rest."""
        echoes = [re.escape(c) for c in self._asked]
        if self.scan is not None:
            mine = re.escape(self.scan.echo()[:-2]) + rb"\d\d" if self.scan.continuous else None
            echoes.append(mine or re.escape(self.scan.echo()))
        if not echoes:
            return frame
        starts = [m.start() for m in re.finditer(b"(?:" + b"|".join(echoes) + rb")\n...\n", frame)]
        if not starts or starts[-1] == 0:
            return frame
        self._drop("truncated", f"a response cut short before {frame[starts[-1] :][:20]!r}")
        return frame[starts[-1] :]

    def _is_scan(self, echo: bytes) -> bool:
        """Whether `echo` is that of the scans asked for (an MD echo counts down its last two
        digits)."""
        if self.scan is None:
            return False
        mine = self.scan.echo()
        return echo == mine if not self.scan.continuous else echo[:-2] == mine[:-2]

    def _drop(self, kind: str, why: str) -> None:
        self.counts[kind] += 1
        _log.info("dropped a frame (%s): %s", kind, why)

    def _answer(self, command: bytes, response: Response, stamp: float) -> None:
        status = response.status
        name = command[:2]
        if name in (b"QT", b"SC"):  # SCIP2.0: "0" from SCIP 1.1 firmware, "0E" from 2.0
            return
        if name == b"BM" and status in ("00", "02") and self.scan is not None:  # 02: it was on
            self._send(self.scan.echo())
            return
        if status != "00":
            self.counts["errors"] += 1
            _log.error("the scanner answers %s with status %s", command.decode(), status)
            return
        try:
            if name == b"VV":
                info = parse_info(response.lines)
                _log.notice(
                    "%s, serial %s, firmware %s",
                    info.get("PROD", "?"),
                    info.get("SERI", "?"),
                    info.get("FIRM", "?"),
                )
            elif name == b"PP":
                self._configure(Geometry.from_info(parse_info(response.lines)))
            elif name == b"II":
                _log.info("status: %s", parse_info(response.lines).get("STAT", "?"))
            elif name in (b"MD", b"MS"):
                self._streaming = True
            elif name in (b"GD", b"GS"):
                self._scan(response, stamp)
        except ScipError as e:
            self._drop(e.kind, f"{command.decode()}: {e}")

    def _configure(self, geometry: Geometry) -> None:
        """The scanner's geometry is known: describe the scans, and ask for them."""
        p = self.params
        first = geometry.amin if p.firstStep < 0 else p.firstStep
        last = geometry.amax if p.lastStep < 0 else p.lastStep
        if not geometry.amin <= first <= last <= geometry.amax:
            _log.error(
                "steps %d to %d are outside the scanner's %d to %d: using those",
                first,
                last,
                geometry.amin,
                geometry.amax,
            )
            first, last = geometry.amin, geometry.amax
        self.geometry = geometry
        self.scan = ScanCommand(first, last, p.cluster, p.encoding, p.continuous, p.skip, 0)
        self.impl.describe(build_description(p, geometry, self.scan))
        _log.notice(
            "%s: steps %d to %d, %d readings a scan, %.1f scans a second",
            geometry.model,
            first,
            last,
            self.scan.values,
            1 / (geometry.period * (p.skip + 1)),
        )
        self._send(self.scan.echo() if p.continuous else b"BM")

    def _scan(self, response: Response, stamp: float) -> None:
        assert self.scan is not None and self.geometry is not None
        if response.status not in ("99", "00"):
            self.counts["errors"] += 1
            _log.error("scan status %s", response.status)
            return
        try:
            device_stamp, values = decode_scan(response.lines, self.scan)
        except ScipError as e:
            self._drop(e.kind, str(e))
            return
        if self._last_stamp is not None:
            ahead = (device_stamp - self._last_stamp) % (1 << 24)
            if ahead == 0 or ahead > 1 << 23:
                self._drop("out of order", f"time stamp {device_stamp} after {self._last_stamp}")
                return
        self._last_stamp = device_stamp
        g = self.geometry
        ranges = array(
            "i",
            [
                RS.INVALID_RANGE if v < g.dmin else RS.HORIZON_RANGE if v > g.dmax else v
                for v in values
            ],
        )
        self.counts["scans"] += 1
        self.impl.integrate_data(Miro.RangeScanEventIDL(to_time(stamp), [ranges]), stamp)
        if not self.scan.continuous:
            self._send(self.scan.echo())  # the next one


def connect(
    device: str, reactor: Reactor, handler: DevEventHandler, params: LaserParameters
) -> Connection:
    """`HOST:PORT` (or tcp://HOST:PORT) is a scanner on Ethernet; anything else a serial port."""
    address = device.removeprefix("tcp://")
    host, colon, port = address.rpartition(":")
    if colon and port.isdigit() and "/" not in address:
        return SockConnection(reactor, handler, host, int(port))
    return TtyConnection(reactor, handler, device, params.ttyParams.pyserial())


def options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", help="serial port, pyserial URL or HOST:PORT (overrides)")


def main(argv: list[str] | None = None) -> int:
    server, args = startup.start("laser", argv, __doc__, options)
    params = LaserParameters.instance()
    startup.read(params, "Laser", server, "laser")
    if args.device:
        params.device = args.device
    try:
        ScanCommand(0, 0, params.cluster, params.encoding, params.continuous, params.skip)
    except ValueError as e:
        startup.fail("laser", e)
    _log.debug("parameters:\n%s", params)
    supplier = startup.supplier_on(server, params.channelName, "laser")
    impl = LaserImpl(supplier, params)
    consumer = ScipConsumer(impl, params)
    framer = LineFramer(b"\n\n", max_length=MAX_FRAME)  # a response ends with an empty line
    handler = DevEventHandler(framer, consumer)
    connection = connect(params.device, server.reactor(), handler, params)
    consumer.connection = connection
    server.add_to_name_service(impl, params.objectName)
    server.reactor().schedule_timer(0.5, 0.5, consumer)
    connection.open()
    print(
        f"laser: reading {params.device}, serving {params.objectName}, "
        f"publishing {params.eventName} on {params.channelName}",
        flush=True,
    )
    server.on_shutdown(connection.close)
    server.run()
    c = consumer.counts
    print(
        f"laser: {c['scans']} scans, {impl.published} published; dropped {c['checksum']} with a "
        f"bad checksum, {c['truncated']} truncated, {c['out of order']} out of order, "
        f"{c['malformed']} malformed, {framer.discarded} noise bytes; {c['errors']} error "
        f"answers, {c['restarts']} restarts, {connection.connects} connections",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    run_main(main, "laser")
