"""NMEA 0183 streams for the GPS simulator: a synthetic vehicle, or a recorded file.

The synthetic vehicle drives laps of a rounded rectangle (200 m by 100 m, near Ottawa by default)
at a steady speed; each fix gets Gaussian position noise of a consumer receiver (about 1.5 m),
and every epoch sends GGA, GSA, RMC and VTG, as common receivers do. A recorded file is replayed
epoch by epoch (an epoch: the sentences up to the next change of the GGA/RMC time), spaced as the
times in it say.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import reduce
from pathlib import Path

EARTH_RADIUS = 6_371_000.0  # metres
KNOT = 1852.0 / 3600.0  # metres per second


@dataclass
class Fix:
    """What the simulated receiver reports for one epoch."""

    time: float  # UTC, seconds since the epoch
    latitude: float
    longitude: float
    altitude: float
    speed: float  # m/s
    course: float  # degrees from true north
    satellites: list[int]
    hdop: float


def checksummed(body: str) -> bytes:
    """`$body*CS` with CR LF."""
    checksum = reduce(lambda a, c: a ^ ord(c), body, 0)
    return f"${body}*{checksum:02X}\r\n".encode("ascii")


def _coordinate(value: float, degree_digits: int, hemispheres: str) -> tuple[str, str]:
    hemisphere = hemispheres[0] if value >= 0 else hemispheres[1]
    value = abs(value)
    degrees = int(value)
    minutes = (value - degrees) * 60
    return f"{degrees:0{degree_digits}d}{minutes:07.4f}", hemisphere


def sentences(fix: Fix) -> list[bytes]:
    """The GGA, GSA, RMC and VTG sentences of one fix."""
    when = datetime.fromtimestamp(fix.time, UTC)
    hms = when.strftime("%H%M%S") + f".{when.microsecond // 10000:02d}"
    lat, ns = _coordinate(fix.latitude, 2, "NS")
    lon, ew = _coordinate(fix.longitude, 3, "EW")
    used = len(fix.satellites)
    prns = [f"{p:02d}" for p in fix.satellites[:12]] + [""] * (12 - min(12, used))
    knots = fix.speed / KNOT
    return [
        checksummed(
            f"GPGGA,{hms},{lat},{ns},{lon},{ew},1,{used:02d},{fix.hdop:.1f},"
            f"{fix.altitude:.1f},M,-34.2,M,,"
        ),
        checksummed(f"GPGSA,A,3,{','.join(prns)},{fix.hdop * 1.8:.1f},{fix.hdop:.1f},1.5"),
        checksummed(
            f"GPRMC,{hms},A,{lat},{ns},{lon},{ew},{knots:.2f},{fix.course:.1f},"
            f"{when.strftime('%d%m%y')},13.5,W"
        ),
        checksummed(f"GPVTG,{fix.course:.1f},T,,M,{knots:.2f},N,{fix.speed * 3.6:.2f},K"),
    ]


def synthetic_fixes(
    start: float,
    *,
    rate: float = 1.0,
    speed: float = 5.0,
    origin: tuple[float, float] = (45.3876, -75.6960),
    noise: float = 1.5,
    seed: int | None = None,
) -> Iterator[Fix]:
    """Fixes `1/rate` seconds apart from UTC time `start`, of a vehicle driving laps at `speed`."""
    rng = random.Random(seed)
    width, height, corner = 200.0, 100.0, 20.0
    straight = [width - 2 * corner, height - 2 * corner] * 2
    lap = sum(straight) + 2 * math.pi * corner
    satellites = sorted(rng.sample(range(1, 33), 9))
    n = 0
    while True:
        t = n / rate
        east, north, course = _on_track(speed * t % lap, straight, corner)
        east += rng.gauss(0, noise)
        north += rng.gauss(0, noise)
        lat = origin[0] + math.degrees(north / EARTH_RADIUS)
        lon = origin[1] + math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(origin[0]))))
        yield Fix(
            start + t,
            lat,
            lon,
            70.0 + rng.gauss(0, noise),
            max(0.0, speed + rng.gauss(0, 0.1)),
            course,
            satellites,
            round(0.9 + abs(rng.gauss(0, 0.2)), 1),
        )
        n += 1


def _on_track(distance: float, straight: list[float], corner: float) -> tuple[float, float, float]:
    """Position (east, north in metres) and course (degrees) `distance` along the lap, which
    runs anticlockwise: east, north, west, south, with quarter circles between."""
    x, y, heading = corner, 0.0, 90.0  # compass course: east
    for side in straight:
        if distance <= side:
            rad = math.radians(heading)
            return x + distance * math.sin(rad), y + distance * math.cos(rad), heading
        rad = math.radians(heading)
        x, y = x + side * math.sin(rad), y + side * math.cos(rad)
        distance -= side
        arc = math.pi / 2 * corner
        if distance <= arc:  # turning left by the fraction of the quarter circle done
            turned = math.degrees(distance / corner)
            cx = x + corner * math.sin(math.radians(heading - 90))
            cy = y + corner * math.cos(math.radians(heading - 90))
            a = math.radians(heading + 90 - turned)
            return cx + corner * math.sin(a), cy + corner * math.cos(a), (heading - turned) % 360
        x, y = _after_turn(x, y, heading, corner)
        heading = (heading - 90) % 360
        distance -= arc
    return x, y, heading


def _after_turn(x: float, y: float, heading: float, corner: float) -> tuple[float, float]:
    fwd, left = math.radians(heading), math.radians(heading - 90)
    return (
        x + corner * (math.sin(fwd) + math.sin(left)),
        y + corner * (math.cos(fwd) + math.cos(left)),
    )


def recorded_epochs(path: Path) -> Iterator[tuple[float | None, list[bytes]]]:
    """The epochs of a recorded NMEA file: (time of day in seconds or None, its lines)."""
    epoch: list[bytes] = []
    epoch_time: float | None = None
    with path.open("rb") as f:
        for raw in f:
            line = raw.strip()
            if not line:
                continue
            t = _time_of(line)
            if t is not None and epoch_time is not None and t != epoch_time and epoch:
                yield epoch_time, epoch
                epoch = []
            if t is not None:
                epoch_time = t
            epoch.append(line + b"\r\n")
    if epoch:
        yield epoch_time, epoch


def _time_of(line: bytes) -> float | None:
    fields = line.split(b",")
    if len(fields) < 2 or fields[0][-3:] not in (b"GGA", b"RMC"):
        return None
    text = fields[1]
    try:
        return int(text[:2]) * 3600 + int(text[2:4]) * 60 + float(text[4:])
    except ValueError:
        return None
