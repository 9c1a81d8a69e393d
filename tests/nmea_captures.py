"""NMEA captures and the fixes they should give, for the GPS driver's tests and bench/.

Two kinds of capture:
- ours, in tests/data/nmea/: synthesised, each with `# expect: TIME LAT LON [ALT]` lines (the
  valid fixes, in order) and `# option: NAME=VALUE` lines (the parser's options);
- real receivers' logs from gpsd's regression suite (BSD-2-Clause), fetched into
  `<checkout>/../shared/captures/gpsd/test/daemon` (or `$MIRO_CAPTURES/gpsd/...`), never
  committed here: `NAME.log` and gpsd's decoding of it, `NAME.log.chk`, whose TPV reports with a
  time, a position and mode 2 or 3 are gpsd's fixes.

A *fix* is (UTC time as ISO 8601 with milliseconds, latitude, longitude). Readings are compared
with fixes by time; positions must agree to 1e-6 degrees (0.1 m).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import Miro

ROOT = Path(__file__).resolve().parents[1]
OURS = ROOT / "tests" / "data" / "nmea"
TOLERANCE = 1e-6  # degrees

Fix = tuple[float, float]  # latitude, longitude


def captures_dir() -> Path | None:
    """Where fetched captures are: $MIRO_CAPTURES, else ../shared/captures beside the checkout
    (a worktree one level deeper looks two levels up)."""
    env = os.environ.get("MIRO_CAPTURES")
    candidates = [Path(env)] if env else []
    candidates += [ROOT.parent / "shared" / "captures", ROOT.parents[1] / "shared" / "captures"]
    return next((c for c in candidates if c.is_dir()), None)


def gpsd_logs() -> list[Path]:
    """gpsd's receiver logs that are NMEA 0183 (nine lines in ten start with `$`), with their
    decodings; empty when the captures are not there."""
    base = captures_dir()
    daemon = base / "gpsd" / "test" / "daemon" if base else None
    if daemon is None or not daemon.is_dir():
        return []
    return [log for log in sorted(daemon.glob("*.log")) if _is_nmea(log) and chk(log).exists()]


def chk(log: Path) -> Path:
    return log.with_name(log.name + ".chk")


def _is_nmea(log: Path) -> bool:
    lines = [x for x in log.read_bytes().split(b"\n") if x.strip() and not x.startswith(b"#")]
    return bool(lines) and sum(x.lstrip().startswith(b"$") for x in lines) >= 0.9 * len(lines)


# Logs that gpsd dates 1024 weeks after their capture (its week-rollover guess misfires when it
# replays them): their fixes are taken with gpsd's times moved back by 1024 weeks.
GPSD_ROLLED = {"neo-m8n.log", "rst39.log"}


def gpsd_fixes(log: Path) -> dict[str, Fix]:
    """gpsd's fixes for `log`: its last TPV report with a time, a position and mode >= 2 for
    each time."""
    fixes: dict[str, Fix] = {}
    for line in chk(log).read_text(errors="replace").splitlines():
        if line.startswith('{"class":"TPV"'):
            tpv = json.loads(line)
            if tpv.get("mode", 0) >= 2 and "time" in tpv and "lat" in tpv:
                time = tpv["time"]
                if log.name in GPSD_ROLLED:
                    when = datetime.strptime(time, "%Y-%m-%dT%H:%M:%S.%fZ") - timedelta(weeks=1024)
                    time = when.strftime("%Y-%m-%dT%H:%M:%S.") + f"{when.microsecond // 1000:03d}Z"
                fixes[time] = (tpv["lat"], tpv["lon"])
    return fixes


def data_lines(log: Path) -> list[bytes]:
    """The lines of a capture the receiver sent (comments dropped), with their line ends."""
    return [x for x in log.read_bytes().splitlines(keepends=True) if not x.startswith(b"#")]


@dataclass
class OurCapture:
    """One of tests/data/nmea: the expected fixes (and altitudes) and the parser's options."""

    path: Path
    fixes: dict[str, Fix] = field(default_factory=dict)
    altitudes: dict[str, float] = field(default_factory=dict)
    options: dict[str, str] = field(default_factory=dict)


def our_captures() -> list[OurCapture]:
    out = []
    for path in sorted(OURS.glob("*.nmea")):
        capture = OurCapture(path)
        for line in path.read_text().splitlines():
            if line.startswith("# expect: "):
                time, lat, lon, *alt = line.removeprefix("# expect: ").split()
                capture.fixes[time] = (float(lat), float(lon))
                if alt:
                    capture.altitudes[time] = float(alt[0])
            elif line.startswith("# option: "):
                name, _, value = line.removeprefix("# option: ").partition("=")
                capture.options[name] = value
        out.append(capture)
    return out


def iso(t: Miro.TimeIDL) -> str:
    """A reading's UTC time as gpsd writes it."""
    when = datetime.fromtimestamp(t.sec, UTC)
    return when.strftime("%Y-%m-%dT%H:%M:%S") + f".{t.usec // 1000:03d}Z"


def valid_fixes(readings: Iterable[Miro.GpsDataIDL]) -> dict[str, Fix]:
    """The fixes among `readings` (the valid ones), by time (a receiver whose clock jumps back
    gives a time twice: the later fix counts, as in gpsd's reports)."""
    return {iso(r.utcTime): (r.latitude, r.longitude) for r in readings if r.valid}


@dataclass
class Comparison:
    """How our fixes compare with the expected ones."""

    missing: list[str]  # expected, not ours
    extra: list[str]  # ours, not expected
    elsewhere: list[str]  # both, positions apart

    @property
    def agree(self) -> bool:
        return not (self.missing or self.extra or self.elsewhere)

    def __str__(self) -> str:
        def some(times: list[str]) -> str:
            return f"{len(times)} ({', '.join(times[:3])}{', ...' if len(times) > 3 else ''})"

        return (
            f"missing {some(self.missing)}, extra {some(self.extra)}, "
            f"elsewhere {some(self.elsewhere)}"
        )


def compare(expected: dict[str, Fix], ours: dict[str, Fix]) -> Comparison:
    both = sorted(set(expected) & set(ours))
    return Comparison(
        missing=sorted(set(expected) - set(ours)),
        extra=sorted(set(ours) - set(expected)),
        elsewhere=[
            t
            for t in both
            if not all(
                math.isclose(a, b, abs_tol=TOLERANCE)
                for a, b in zip(expected[t], ours[t], strict=True)
            )
        ],
    )
