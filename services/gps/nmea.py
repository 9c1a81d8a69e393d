"""NMEA 0183 sentences (GGA, RMC, VTG, GSA) into Miro::GpsDataIDL readings.

Each sentence's checksum is verified; a sentence that fails it, or whose fields do not parse,
is counted and skipped, and the reading keeps its last good values. A sentence type this parser
does not use (GSV, proprietary `$P...`) is counted as ignored. GGA and RMC, the sentences that
carry a position, each complete a reading; GSA and VTG update the fields they carry, which go out
with the next reading. Fields never received (or left empty by the receiver) are NaN or 0, as
the IDL says.

pynmea2 was considered: it turns empty coordinates into 0.0 (a valid position) and passes
unparsable times through as strings, so its fields would need the same checks as raw ones.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from datetime import UTC, datetime

import Miro

KNOT = 1852.0 / 3600.0  # metres per second
NAN = math.nan


class NmeaError(ValueError):
    """A sentence that is not good NMEA; `kind` is "checksum" or "malformed"."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def split_sentence(line: bytes) -> tuple[str, list[str]]:
    """The sentence's type (talker dropped: `GGA`) and its fields, after checking the checksum.
    Proprietary sentences have the type `P` + maker + type."""
    text = line.strip()
    if not text.startswith(b"$"):
        raise NmeaError("malformed", "does not start with '$'")
    body, star, checksum = text[1:].rpartition(b"*")
    if not star:
        raise NmeaError("checksum", "no checksum")
    try:
        expected = int(checksum, 16)
    except ValueError:
        raise NmeaError("checksum", f"checksum {checksum!r} is not hexadecimal") from None
    actual = 0
    for byte in body:
        actual ^= byte
    if len(checksum) != 2 or actual != expected:
        raise NmeaError("checksum", f"checksum {actual:02X} != {checksum.decode('latin-1')}")
    try:
        fields = body.decode("ascii").split(",")
    except UnicodeDecodeError:
        raise NmeaError("malformed", "not ASCII") from None
    address = fields[0]
    if address.startswith("P"):
        return address, fields[1:]
    if len(address) != 5 or not address.isalnum():
        raise NmeaError("malformed", f"address {address!r}")
    return address[2:], fields[1:]


def _number(text: str) -> float:
    if not text:
        return NAN
    try:
        value = float(text)
    except ValueError:
        raise NmeaError("malformed", f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise NmeaError("malformed", f"{text!r} is not a finite number")
    return value


def _integer(text: str, high: int) -> int:
    if not text:
        return 0
    if not text.isdigit() or int(text) > high:
        raise NmeaError("malformed", f"{text!r} is not an integer from 0 to {high}")
    return int(text)


def _angle(value: str, hemisphere: str, negative: str, degree_digits: int) -> float:
    """`ddmm.mmmm` / `dddmm.mmmm` and N/S or E/W into signed degrees (NaN when empty)."""
    if not value and not hemisphere:
        return NAN
    if hemisphere not in ("NS" if negative == "S" else "EW") or len(hemisphere) != 1:
        raise NmeaError("malformed", f"hemisphere {hemisphere!r}")
    if len(value.split(".")[0]) != degree_digits + 2:
        raise NmeaError("malformed", f"coordinate {value!r}")
    degrees = _number(value[:degree_digits])
    minutes = _number(value[degree_digits:])
    if minutes >= 60 or degrees > 90 * (degree_digits - 1):
        raise NmeaError("malformed", f"coordinate {value!r}")
    result = degrees + minutes / 60
    return -result if hemisphere == negative else result


def _time_of_day(text: str) -> float | None:
    """`hhmmss[.ss]` into seconds since midnight (None when empty)."""
    if not text:
        return None
    if len(text) < 6 or not text[:6].isdigit():
        raise NmeaError("malformed", f"time {text!r}")
    h, m, s = int(text[:2]), int(text[2:4]), _number(text[4:])
    if h > 23 or m > 59 or s >= 61:
        raise NmeaError("malformed", f"time {text!r}")
    return h * 3600 + m * 60 + s


def _date(text: str) -> float | None:
    """`ddmmyy` into seconds since the epoch at that day's midnight (None when empty)."""
    if not text:
        return None
    try:
        day = datetime.strptime(text, "%d%m%y").replace(tzinfo=UTC)
    except ValueError:
        raise NmeaError("malformed", f"date {text!r}") from None
    return day.timestamp()


def _time(seconds: float) -> Miro.TimeIDL:
    sec = math.floor(seconds)
    return Miro.TimeIDL(sec, min(999_999, round((seconds - sec) * 1e6)))


def empty_reading() -> Miro.GpsDataIDL:
    """A reading with nothing received yet: NaN floats, zero integers."""
    return Miro.GpsDataIDL(
        latitude=NAN,
        longitude=NAN,
        altitude=NAN,
        geoidSeparation=NAN,
        hdop=NAN,
        pdop=NAN,
        vdop=NAN,
        speed=NAN,
        course=NAN,
        magneticVariation=NAN,
        dgpsAge=NAN,
    )


@dataclass
class Counts:
    """What the parser has seen, by outcome."""

    good: int = 0  # sentences used
    ignored: int = 0  # good sentences of types not used here
    checksum: int = 0  # bad or missing checksum
    malformed: int = 0  # good checksum, fields that do not parse


class NmeaParser:
    """Keeps the receiver's state; `feed(sentence, stamp)` returns a new reading when the
    sentence completes one (GGA, RMC), else None."""

    def __init__(self) -> None:
        self.reading = empty_reading()
        self.counts = Counts()
        self._date: float | None = None  # midnight of the last RMC date
        self._rmc_time: float | None = None

    def feed(self, sentence: bytes, stamp: float) -> Miro.GpsDataIDL | None:
        try:
            kind, fields = split_sentence(sentence)
            handler = _HANDLERS.get(kind)
            if handler is None:
                self.counts.ignored += 1
                return None
            update = handler(self, fields)
        except NmeaError as e:
            if e.kind == "checksum":
                self.counts.checksum += 1
            else:
                self.counts.malformed += 1
            return None
        self.counts.good += 1
        for name, value in update.items():  # all fields parsed: apply them together
            setattr(self.reading, name, value)
        if kind not in ("GGA", "RMC"):
            return None
        self.reading.time = _time(stamp)
        return copy.deepcopy(self.reading)

    def _utc(self, time_of_day: float | None) -> Miro.TimeIDL:
        if time_of_day is None:
            return self.reading.utcTime
        if self._date is None:
            return _time(time_of_day)
        day = self._date
        if self._rmc_time is not None and time_of_day < self._rmc_time - 12 * 3600:
            day += 86400  # past midnight since the last RMC
        return _time(day + time_of_day)

    def _gga(self, f: list[str]) -> dict[str, object]:
        if len(f) < 14:
            raise NmeaError("malformed", f"GGA has {len(f)} fields")
        quality = _integer(f[5], 8)
        return {
            "utcTime": self._utc(_time_of_day(f[0])),
            "latitude": _angle(f[1], f[2], "S", 2),
            "longitude": _angle(f[3], f[4], "W", 3),
            "quality": Miro.GpsFixQualityIDL(quality),
            "valid": quality > 0,
            "satellitesUsed": _integer(f[6], 99),
            "hdop": _number(f[7]),
            "altitude": _number(f[8]),
            "geoidSeparation": _number(f[10]),
            "dgpsAge": _number(f[12]),
            "dgpsStation": _integer(f[13], 1023),
        }

    def _rmc(self, f: list[str]) -> dict[str, object]:
        if len(f) < 11:
            raise NmeaError("malformed", f"RMC has {len(f)} fields")
        if f[1] not in ("A", "V"):
            raise NmeaError("malformed", f"RMC status {f[1]!r}")
        time_of_day, date = _time_of_day(f[0]), _date(f[8])
        variation = _number(f[9])
        if f[10] == "W":
            variation = -variation
        if date is not None:
            self._date, self._rmc_time = date, time_of_day
        return {
            "utcTime": self._utc(time_of_day),
            "valid": f[1] == "A",
            "latitude": _angle(f[2], f[3], "S", 2),
            "longitude": _angle(f[4], f[5], "W", 3),
            "speed": _number(f[6]) * KNOT,
            "course": _number(f[7]),
            "magneticVariation": variation,
        }

    def _vtg(self, f: list[str]) -> dict[str, object]:
        if len(f) < 8:
            raise NmeaError("malformed", f"VTG has {len(f)} fields")
        return {"course": _number(f[0]), "speed": _number(f[6]) / 3.6}

    def _gsa(self, f: list[str]) -> dict[str, object]:
        if len(f) < 17:
            raise NmeaError("malformed", f"GSA has {len(f)} fields")
        return {
            "mode": Miro.GpsFixModeIDL(_integer(f[1], 3)),
            "satellites": [_integer(prn, 0xFFFF) for prn in f[2:14] if prn],
            "pdop": _number(f[14]),
            "hdop": _number(f[15]),
            "vdop": _number(f[16]),
        }


_HANDLERS = {
    "GGA": NmeaParser._gga,
    "RMC": NmeaParser._rmc,
    "VTG": NmeaParser._vtg,
    "GSA": NmeaParser._gsa,
}
