"""Hokuyo's SCIP 2.0 protocol (URG, UTM, UST laser scanners): commands, responses, the
character encodings. The one owner of its facts, for the laser driver and its simulator.

A command is ASCII ending with LF: `VV` (version), `PP` (parameters), `II` (status), `BM`
(laser on), `QT` (laser off, stop), `GDsssseeeecc` (one scan, steps s to e, cc steps per
cluster), `MDsssseeeeccinn` (scans every i+1 rotations, nn of them, 00 = until QT). `GS`/`MS` are
the same with two-character values (up to 4095 mm), `GD`/`MD` with three (up to 262143 mm).

A response is the command echoed, a two-character status and its checksum, the data lines,
each with its checksum, and an empty line: `echo LF status sum LF (line sum LF)* LF`. The
checksum of a line is the sum of its bytes, its low six bits plus 0x30. Status `00` is success;
`99` marks each scan of an MD; `0E`-style codes are errors. A scan's first data line is a
four-character time stamp (milliseconds, wrapping at 2^24), then the values, 64 characters a
line, a value possibly split across two lines. An MD is answered with its echo and `00` once,
then with one response per scan whose echo carries the number of scans still to come.

In the replies to VV, PP and II each line is `NAME:value;` and its checksum, which some
firmware computes without the `;` (urg_library accepts both; so do we).

Facts from Hokuyo's SCIP 2.0 specification as urg_library and urg_node implement it; no code
was taken from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

LINE_VALUES = 64  # data characters per line
STAMP_WRAP = 1 << 24  # the time stamp counts milliseconds in 24 bits
OK, SCAN = "00", "99"


class ScipError(ValueError):
    """A response that is not good SCIP; `kind`: "checksum", "truncated" or "malformed"."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def checksum(data: bytes) -> int:
    """SCIP's line checksum: the sum of the bytes' low six bits, plus 0x30."""
    return (sum(data) & 0x3F) + 0x30


def with_sum(data: bytes) -> bytes:
    """A line with its checksum appended (no LF)."""
    return data + bytes([checksum(data)])


def encode(value: int, width: int) -> bytes:
    """`value` in `width` characters of six bits each (0x30 added), most significant first."""
    if not 0 <= value < 1 << (6 * width):
        raise ValueError(f"{value} does not fit in {width} SCIP characters")
    return bytes(((value >> (6 * (width - 1 - i))) & 0x3F) + 0x30 for i in range(width))


def decode(chars: bytes) -> int:
    value = 0
    for c in chars:
        if not 0x30 <= c < 0x70:
            raise ScipError("malformed", f"{chars!r} is not SCIP-encoded")
        value = (value << 6) | (c - 0x30)
    return value


# ---- commands ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ScanCommand:
    """A GD/GS (single) or MD/MS (continuous) request."""

    start: int
    end: int
    cluster: int = 1
    encoding: int = 3  # characters per value: 3 (GD/MD) or 2 (GS/MS)
    continuous: bool = True
    interval: int = 0  # MD: skip this many rotations between scans (0-9)
    count: int = 0  # MD: this many scans, 0 = until QT

    def __post_init__(self) -> None:
        if self.encoding not in (2, 3):
            raise ValueError("the encoding is 2 or 3 characters a value")
        if not (0 <= self.start <= self.end <= 9999 and 1 <= self.cluster <= 99):
            raise ValueError("steps 0 <= start <= end <= 9999 and a cluster of 1 to 99")
        if not (0 <= self.interval <= 9 and 0 <= self.count <= 99):
            raise ValueError("an interval of 0 to 9 and a count of 0 to 99")

    @property
    def name(self) -> str:
        return ("M" if self.continuous else "G") + ("D" if self.encoding == 3 else "S")

    def echo(self, remaining: int | None = None) -> bytes:
        """The command line without LF; an MD scan's echo carries `remaining` instead of the
        count."""
        text = f"{self.name}{self.start:04d}{self.end:04d}{self.cluster:02d}"
        if self.continuous:
            text += f"{self.interval:d}{self.count if remaining is None else remaining:02d}"
        return text.encode("ascii")

    def command(self) -> bytes:
        return self.echo() + b"\n"

    @property
    def values(self) -> int:
        """Values in each scan."""
        return math.ceil((self.end - self.start + 1) / self.cluster)

    @classmethod
    def parse(cls, echo: bytes) -> ScanCommand:
        """The command an echo repeats (an MD echo's count is its remaining scans)."""
        text = echo.decode("ascii", "replace")
        kind, digits = text[:2], text[2:]
        if kind not in ("GD", "GS", "MD", "MS") or not digits.isdigit():
            raise ScipError("malformed", f"not a scan command: {text!r}")
        continuous = kind[0] == "M"
        if len(digits) != (13 if continuous else 10):
            raise ScipError("malformed", f"not a scan command: {text!r}")
        try:
            return cls(
                int(digits[:4]),
                int(digits[4:8]),
                int(digits[8:10]) or 1,
                3 if kind[1] == "D" else 2,
                continuous,
                int(digits[10:11] or 0),
                int(digits[11:13] or 0),
            )
        except ValueError as e:
            raise ScipError("malformed", f"{text!r}: {e}") from None


# ---- responses --------------------------------------------------------------------------------


@dataclass
class Response:
    """One response: the echoed command, the status, the data lines (checksums verified and
    removed)."""

    echo: bytes
    status: str
    lines: list[bytes]


def split_response(frame: bytes) -> Response:
    """A response (a frame up to, not including, its empty line) into its parts, checking every
    checksum. A status of one character is SCIP 1.1's answer to `SCIP2.0` (no checksum)."""
    lines = frame.split(b"\n")
    if len(lines) < 2:
        raise ScipError("truncated", f"no status after {lines[0][:20]!r}")
    echo, status, *data = lines
    if len(status) == 1:
        return Response(echo, status.decode("ascii", "replace"), [])
    if len(status) != 3 or status[2] != checksum(status[:2]):
        raise ScipError("checksum" if len(status) == 3 else "malformed", f"status {status!r}")
    out = []
    for line in data:
        summed = bool(line) and line[-1] == checksum(line[:-1])
        # Info lines (NAME:value;) may be summed without their ';'.
        info = len(line) > 2 and line[-2:-1] == b";" and line[-1] == checksum(line[:-2])
        if not (summed or info):
            raise ScipError("checksum", f"line {line[:20]!r}")
        out.append(line[:-1])
    return Response(echo, status[:2].decode("ascii"), out)


def parse_info(lines: list[bytes]) -> dict[str, str]:
    """The `NAME:value;` lines of a VV, PP or II reply."""
    info = {}
    for line in lines:
        text = line.decode("ascii", "replace").rstrip(";")
        name, colon, value = text.partition(":")
        if not colon:
            raise ScipError("malformed", f"info line {text!r}")
        info[name] = value
    return info


def decode_scan(lines: list[bytes], command: ScanCommand) -> tuple[int, list[int]]:
    """A scan's time stamp (ms) and its values (mm), from its data lines."""
    if not lines or len(lines[0]) != 4:
        raise ScipError("truncated", "no time stamp")
    stamp = decode(lines[0])
    data = b"".join(lines[1:])
    width = command.encoding
    if len(data) != command.values * width:
        raise ScipError(
            "truncated", f"{len(data) // width} values of {command.values} ({len(data)} chars)"
        )
    return stamp, [decode(data[i : i + width]) for i in range(0, len(data), width)]


# ---- what the device sends (for simulators) --------------------------------------------------


def response(echo: bytes, status: str, lines: list[bytes] = ()) -> bytes:  # type: ignore[assignment]
    """A whole response: echo, status, data lines (checksums added), the empty line."""
    out = [echo, with_sum(status.encode("ascii"))] + [with_sum(line) for line in lines]
    return b"\n".join(out) + b"\n\n"


def scan_lines(stamp: int, values: list[int], encoding: int) -> list[bytes]:
    """The data lines of a scan: time stamp, then the values cut into 64-character lines."""
    data = b"".join(encode(v, encoding) for v in values)
    return [encode(stamp % STAMP_WRAP, 4)] + [
        data[i : i + LINE_VALUES] for i in range(0, len(data), LINE_VALUES)
    ]


def info_lines(info: dict[str, str]) -> list[bytes]:
    return [f"{name}:{value};".encode("ascii") for name, value in info.items()]


# ---- the device's geometry --------------------------------------------------------------------


@dataclass(frozen=True)
class Geometry:
    """What PP says: ranges (mm), angular resolution (steps a turn), first, last and front
    step, rotation speed (rpm)."""

    model: str
    dmin: int
    dmax: int
    ares: int
    amin: int
    amax: int
    afrt: int
    rpm: int

    @classmethod
    def from_info(cls, info: dict[str, str]) -> Geometry:
        def number(name: str) -> int:
            text = info.get(name, "")
            digits = text.split("(")[0].strip()  # "600" or "600(rpm)" on some firmware
            if not digits.isdigit():
                raise ScipError("malformed", f"PP {name}: {text!r}")
            return int(digits)

        geometry = cls(
            info.get("MODL", "?"),
            *(number(n) for n in ("DMIN", "DMAX", "ARES", "AMIN", "AMAX", "AFRT", "SCAN")),
        )
        if not (geometry.ares > 0 and geometry.amin <= geometry.afrt <= geometry.amax):
            raise ScipError("malformed", f"PP geometry {geometry}")
        return geometry

    def info(self) -> dict[str, str]:
        return {
            "MODL": self.model,
            "DMIN": str(self.dmin),
            "DMAX": str(self.dmax),
            "ARES": str(self.ares),
            "AMIN": str(self.amin),
            "AMAX": str(self.amax),
            "AFRT": str(self.afrt),
            "SCAN": str(self.rpm),
        }

    def angle(self, step: float) -> float:
        """The direction of `step` in radians, counter-clockwise from the front."""
        return (step - self.afrt) * 2 * math.pi / self.ares

    @property
    def period(self) -> float:
        """Seconds a rotation takes."""
        return 60.0 / self.rpm


# Two common models, as their PP replies give them.
URG_04LX = Geometry("URG-04LX(Hokuyo Automatic Co.,Ltd.)", 20, 5600, 1024, 44, 725, 384, 600)
UTM_30LX = Geometry("UTM-30LX(Hokuyo Automatic Co.,Ltd.)", 23, 60000, 1440, 0, 1080, 540, 2400)
MODELS = {"URG-04LX": URG_04LX, "UTM-30LX": UTM_30LX}
