"""A Hokuyo laser scanner speaking SCIP 2.0, for `miro sim scip` and the laser driver's tests.

`ScipDevice` answers commands (SCIP2.0, VV, PP, II, BM, QT, RS, GD/GS, MD/MS) as the model's
firmware does and produces the scans an MD asks for, at the model's rotation rate, from a scene:
`RoomScene` (a rectangular room with a round pillar going to and fro, computed by casting a ray
per step) or `RecordedScene` (scans read from a file: one scan per line, whitespace-separated
millimetres, or an MCAP log of `Miro::RangeScanEventIDL` events such as `miro log record`
writes of the laser driver). Where nothing reflects within range the device reports error code
1, as URG scanners do for a weak echo.

`Faults` makes it misbehave on purpose, every Nth scan: a wrong checksum, a scan cut short, an
old scan again (out of order). `ScipServer` runs a device on a pseudo-terminal or a TCP port,
optionally writing in small random pieces.
"""

from __future__ import annotations

import math
import random
import select
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from miro_gen.devices import scip
from miro_gen.devices.scip import Geometry, ScanCommand
from miro_gen.sim.pty_device import PtyDevice

NO_ECHO = 1  # the error code reported where nothing reflects within range


class Scene(Protocol):
    def ranges(self, t: float, geometry: Geometry) -> list[int]:
        """The distances (mm, or an error code) at every step from AMIN to AMAX at time t."""


@dataclass
class RoomScene:
    """The scanner at (x, y) in a `width` by `depth` room (mm), looking along +x, with a pillar
    of radius `pillar` mm going to and fro across the room in front of it every `period` s."""

    width: float = 6000.0
    depth: float = 4000.0
    x: float = 1500.0
    y: float = 2000.0
    pillar: float = 150.0
    period: float = 10.0

    def pillar_at(self, t: float) -> tuple[float, float]:
        phase = math.sin(2 * math.pi * t / self.period)
        return self.x + 1500.0, self.y + phase * (self.depth / 2 - 2 * self.pillar)

    def ranges(self, t: float, geometry: Geometry) -> list[int]:
        px, py = self.pillar_at(t)
        out = []
        for step in range(geometry.amin, geometry.amax + 1):
            a = geometry.angle(step)
            d = self._cast(math.cos(a), math.sin(a), px, py)
            out.append(round(d) if geometry.dmin <= d <= geometry.dmax else NO_ECHO)
        return out

    def _cast(self, dx: float, dy: float, px: float, py: float) -> float:
        """Distance from the scanner to the first wall or the pillar along (dx, dy)."""
        hits = []
        for wall, pos, d in ((0.0, self.x, dx), (self.width, self.x, dx)):
            if d:
                hits.append((wall - pos) / d)
        for wall, pos, d in ((0.0, self.y, dy), (self.depth, self.y, dy)):
            if d:
                hits.append((wall - pos) / d)
        best = min(h for h in hits if h > 0)
        ox, oy = self.x - px, self.y - py  # ray-circle intersection
        b = ox * dx + oy * dy
        c = ox * ox + oy * oy - self.pillar**2
        disc = b * b - c
        if disc >= 0:
            near = -b - math.sqrt(disc)
            if 0 < near < best:
                best = near
        return best


@dataclass
class RecordedScene:
    """Scans played in a loop, one per rotation; resampled to the model's number of steps."""

    scans: list[list[int]]

    def __post_init__(self) -> None:
        if not self.scans or not all(self.scans):
            raise ValueError("a recorded scene needs at least one non-empty scan")

    def ranges(self, t: float, geometry: Geometry) -> list[int]:
        scan = self.scans[int(t / geometry.period) % len(self.scans)]
        n = geometry.amax - geometry.amin + 1
        return [max(0, scan[i * len(scan) // n]) for i in range(n)]

    @classmethod
    def load(cls, path: Path) -> RecordedScene:
        """From a text file (a scan per line) or an MCAP log of RangeScanEventIDL events (group
        0 of each; negative readings, Miro's INVALID_RANGE and HORIZON_RANGE, become 0)."""
        if path.suffix == ".mcap":
            return cls(_mcap_scans(path))
        scans = []
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if line.strip() and not line.lstrip().startswith("#"):
                try:
                    scans.append([int(v) for v in line.split()])
                except ValueError:
                    raise ValueError(f"{path}:{number}: not a line of integers") from None
        return cls(scans)


def _mcap_scans(path: Path) -> list[list[int]]:
    import Miro
    from mcap.reader import make_reader

    scans = []
    with path.open("rb") as f:
        for schema, _, message in make_reader(f).iter_messages():
            if schema is not None and schema.name == "Miro::RangeScanEventIDL":
                event = Miro.RangeScanEventIDL.deserialize(message.data)
                if event.range:
                    scans.append([max(0, v) for v in event.range[0]])
    return scans


@dataclass
class Faults:
    """Every `corrupt`-th scan with a wrong checksum, every `truncate`-th cut short, every
    `repeat`-th followed by an old scan again (0: never)."""

    corrupt: int = 0
    truncate: int = 0
    repeat: int = 0
    sent: dict[str, int] = field(default_factory=lambda: {"corrupt": 0, "truncate": 0, "repeat": 0})


class ScipDevice:
    """The firmware: `handle(line)` answers a command; `due(now)` gives the MD scans due."""

    def __init__(
        self,
        geometry: Geometry,
        scene: Scene,
        *,
        serial: str = "H1234567",
        faults: Faults | None = None,
    ) -> None:
        self.geometry = geometry
        self.scene = scene
        self.serial = serial
        self.faults = faults or Faults()
        self.laser = False
        self.scans = 0  # scans sent
        self._start = time.monotonic()
        self._md: ScanCommand | None = None  # streaming
        self._gd: ScanCommand | None = None  # a single scan asked for
        self._remaining = 0
        self._next = 0.0
        self._old: bytes | None = None

    def stamp(self, now: float) -> int:
        return int((now - self._start) * 1000)

    def handle(self, line: bytes, now: float) -> bytes:
        """The response to one command line (without its LF)."""
        text = line.decode("ascii", "replace")
        g = self.geometry
        if text == "SCIP2.0":
            return scip.response(line, "0E")  # already speaking SCIP 2.0
        if text.startswith("VV"):
            return scip.response(line, scip.OK, scip.info_lines(self._version()))
        if text.startswith("PP"):
            return scip.response(line, scip.OK, scip.info_lines(g.info()))
        if text.startswith("II"):
            return scip.response(line, scip.OK, scip.info_lines(self._status(now)))
        if text.startswith("BM"):
            status = "02" if self.laser else scip.OK
            self.laser = True
            return scip.response(line, status)
        if text.startswith(("QT", "RS")):
            self.laser, self._md, self._gd = False, None, None
            return scip.response(line, scip.OK)
        try:
            command = ScanCommand.parse(line)
        except scip.ScipError:
            return scip.response(line, "0E")  # unknown command
        if not g.amin <= command.start <= command.end <= g.amax:
            return scip.response(line, "04")  # steps out of range
        if not command.continuous:  # answered with the next rotation's scan
            if not self.laser:
                return scip.response(line, "10")  # the laser is off
            self._gd = command
            self._next = max(self._next, now) if self._md else now + g.period
            return b""
        self.laser, self._md, self._remaining = True, command, command.count
        self._next = now + g.period
        return scip.response(line, scip.OK)

    def _version(self) -> dict[str, str]:
        return {
            "VEND": "Hokuyo Automatic Co.,Ltd.",
            "PROD": self.geometry.model.split("(")[0],
            "FIRM": "3.4.03(17/Dec./2012)",
            "PROT": "SCIP 2.0",
            "SERI": self.serial,
        }

    def _status(self, now: float) -> dict[str, str]:
        return {
            "MODL": self.geometry.model.split("(")[0],
            "LASR": "ON" if self.laser else "OFF",
            "SCSP": f"Initial({self.geometry.rpm}[rpm])",
            "MESM": "Measuring by Normal Mode",
            "SBPS": "USB only",
            "TIME": scip.encode(self.stamp(now) % scip.STAMP_WRAP, 4).decode(),
            "STAT": "Stable 000 no error.",
        }

    def due(self, now: float) -> list[bytes]:
        """The scans whose time has come (MD's, a GD's), with the faults asked for."""
        out: list[bytes] = []
        if self._gd is not None and now >= self._next and self._md is None:
            command, self._gd = self._gd, None
            self._next = now + self.geometry.period
            out += self._with_faults(
                scip.response(command.echo(), scip.OK, self._scan_lines(command, now))
            )
        while self._md is not None and now >= self._next:
            command = self._md
            self._next += self.geometry.period * (command.interval + 1)
            if command.count:
                self._remaining -= 1
                if self._remaining <= 0:
                    self._md, self.laser = None, False
            out += self._with_faults(
                scip.response(
                    command.echo(self._remaining if command.count else 0),
                    scip.SCAN,
                    self._scan_lines(command, now),
                )
            )
        return out

    def next_due(self) -> float | None:
        return self._next if self._md is not None or self._gd is not None else None

    def _scan_lines(self, command: ScanCommand, now: float) -> list[bytes]:
        g = self.geometry
        ranges = self.scene.ranges(now - self._start, g)
        steps = ranges[command.start - g.amin : command.end - g.amin + 1]
        limit = (1 << (6 * command.encoding)) - 1
        values = [  # a cluster reports its nearest reading, as the firmware does
            min(min(steps[i : i + command.cluster]), limit)
            for i in range(0, len(steps), command.cluster)
        ]
        self.scans += 1
        return scip.scan_lines(self.stamp(now), values, command.encoding)

    def _with_faults(self, frame: bytes) -> list[bytes]:
        f, n = self.faults, self.scans
        old, self._old = self._old, frame
        if f.corrupt and n % f.corrupt == 0:
            f.sent["corrupt"] += 1
            at = frame.index(b"\n", frame.index(b"\n") + 1) + 3  # in the time stamp line
            return [frame[:at] + bytes([frame[at] ^ 0x01]) + frame[at + 1 :]]
        if f.truncate and n % f.truncate == 0:
            f.sent["truncate"] += 1
            return [frame[: len(frame) // 2]]
        if f.repeat and n % f.repeat == 0 and old is not None:
            f.sent["repeat"] += 1
            return [frame, old]
        return [frame]


class Link(Protocol):
    """Where the device's bytes go: a pseudo-terminal or a TCP connection."""

    def fileno(self) -> int: ...
    def read(self) -> bytes | None: ...  # None: the other end went away
    def write(self, data: bytes) -> None: ...
    def close(self) -> None: ...


class PtyLink:
    def __init__(self, link: Path | None) -> None:
        self.device = PtyDevice(link)
        self.path = self.device.path

    def fileno(self) -> int:
        return self.device.master

    def read(self) -> bytes | None:
        try:
            import os

            return os.read(self.device.master, 4096)
        except BlockingIOError:
            return b""
        except OSError:  # EIO: nobody has the terminal open (yet)
            return b""

    def write(self, data: bytes) -> None:
        self.device.write(data, wait=1.0)

    def vanish(self) -> None:
        self.device.vanish()

    def appear(self) -> None:
        self.device.appear()

    def close(self) -> None:
        self.device.close()


class TcpLink:
    """A listening TCP port; one client at a time (as the scanners serve)."""

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        self.listener = socket.create_server((host, port))
        self.port = self.listener.getsockname()[1]
        self.path = f"{host}:{self.port}"
        self.client: socket.socket | None = None

    def fileno(self) -> int:
        return (self.client or self.listener).fileno()

    def read(self) -> bytes | None:
        if self.client is None:
            self.client, _ = self.listener.accept()
            return b""
        try:
            data = self.client.recv(4096)
        except OSError:
            data = b""
        if not data:
            self.client.close()
            self.client = None
            return None
        return data

    def write(self, data: bytes) -> None:
        if self.client is not None:
            try:
                self.client.sendall(data)
            except OSError:
                self.client.close()
                self.client = None

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        self.listener.close()


class ScipServer:
    """Runs `device` on `link` until `stop()`: reads commands, writes answers and scans, in
    pieces of 1 to `split` bytes when `split` is set (reads then return partial frames)."""

    def __init__(self, device: ScipDevice, link: Link, *, split: int = 0, seed: int = 0) -> None:
        self.device = device
        self.link = link
        self.split = split
        self._rng = random.Random(seed)
        self._buffer = b""
        self._stop = threading.Event()
        self._paused = threading.Event()
        self._idle = threading.Event()  # set while paused, once the loop has seen it
        self.commands = 0

    def run(self, until: Callable[[], bool] = lambda: False) -> None:
        while not self._stop.is_set() and not until():
            if self._paused.is_set():  # unplugged: the device forgets what it was doing
                self.device.handle(b"RS", time.monotonic())
                self._idle.set()
                time.sleep(0.01)
                continue
            self._idle.clear()
            due = self.device.next_due()
            wait = 0.05 if due is None else max(0.0, min(0.05, due - time.monotonic()))
            try:
                readable = select.select([self.link], [], [], wait)[0]
            except (OSError, ValueError):  # the link was closed under us
                time.sleep(0.01)
                continue
            if readable:
                data = self.link.read()
                if data is None:  # the client left: a scanner stops streaming
                    self.device.handle(b"QT", time.monotonic())
                    self._buffer = b""
                    continue
                self._buffer += data.replace(b"\r", b"\n")
                while b"\n" in self._buffer:
                    line, self._buffer = self._buffer.split(b"\n", 1)
                    if line:
                        self.commands += 1
                        answer = self.device.handle(line, time.monotonic())
                        if answer:
                            self._send(answer)
            for frame in self.device.due(time.monotonic()):
                self._send(frame)

    def _send(self, data: bytes) -> None:
        if not self.split:
            self.link.write(data)
            return
        at = 0
        while at < len(data):
            n = self._rng.randint(1, self.split)
            self.link.write(data[at : at + n])
            at += n

    def pause(self, paused: bool) -> None:
        """Stop (or resume) reading and writing, as while the device is unplugged; returns once
        the server has stopped touching the link."""
        if paused:
            self._paused.set()
            self._idle.wait(5)
        else:
            self._buffer = b""
            self._paused.clear()

    def stop(self) -> None:
        self._stop.set()

    def start(self) -> threading.Thread:
        thread = threading.Thread(target=self.run, name="scip-sim", daemon=True)
        thread.start()
        return thread


def make_scene(source: Path | None) -> Scene:
    return RoomScene() if source is None else RecordedScene.load(source)


__all__: Sequence[str] = [
    "Faults",
    "PtyLink",
    "RecordedScene",
    "RoomScene",
    "ScipDevice",
    "ScipServer",
    "TcpLink",
    "make_scene",
]
