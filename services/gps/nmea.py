"""NMEA 0183 sentences: checksum, fields, and what each sentence says about its fix.

Read: GGA, RMC, GNS and GLL (position), GSA (mode, satellites, DOPs), VTG (course and speed), ZDA
(date with a four-digit year) and Garmin's `$PGRMZ` (altitude), from any talker (GP, GN, GL, GA,
GB, BD, ...). `decode(line)` checks the checksum and returns a `Sentence`: the Miro::GpsDataIDL
fields it sets, its UTC time and date, and what it says about the fix: whether there is one
(`fix`) and of what kind (`quality`). A sentence that fails its checksum, or whose fields do not
parse, raises `NmeaError`; one of another type decodes to None. services/gps/nmea_epochs.py puts
the sentences of one fix together.

What the sentences say (NMEA 0183 4.11; receivers' quirks as gpsd's test logs show them):
- GGA fix quality: 0 no fix; 1 GPS, 2 DGPS, 3 PPS, 4 RTK, 5 float RTK: a fix; 6 estimated (dead
  reckoning), 7 manual input, 8 simulation: a position that is not a fix from the sky. A GP or GN
  GGA with fewer than 3 satellites used has no fix, whatever its quality (receivers that lose
  the satellites keep quality 1 and the last position with 0 satellites).
- RMC and GLL status: `A` a fix, `V` none (an RMC `V`'s date is not used: receivers without a fix
  send stale or made-up dates).
- RMC, GLL and GNS mode indicators (NMEA 2.3 and later): `A` autonomous, `D` differential, `P`
  precise, `R` RTK, `F` float RTK: a fix; `E` estimated, `M` manual, `S` simulated: not a fix from
  the sky; `N` (and `V` on some receivers) no fix. GNS has one letter per constellation (GPS,
  GLONASS, Galileo, BeiDou, QZSS, NavIC): the best of them counts. A GNS whose navigational status
  (NMEA 4.1) is `U`, unsafe, says nothing about the fix.
- GSA fix mode: 1 no fix, 2 and 3 a fix (u-blox Antaris's `E`: estimated).
- RMC's year has two digits: 80 to 99 are 1980 to 1999 (GPS time starts in 1980), 00 to 79 are
  2000 to 2079. ZDA has four.

pynmea2 was considered: it turns empty coordinates into 0.0 (a valid position) and passes
unparsable times through as strings, so its fields would need the same checks as raw ones.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime

import Miro

KNOT = 1852.0 / 3600.0  # metres per second
FOOT = 0.3048  # metres
NAN = math.nan
Q = Miro.GpsFixQualityIDL

# What an RMC, GLL or GNS mode indicator (NMEA 2.3 and later) says about the fix.
MODE_QUALITY = {
    "A": Q.GPS_FIX_GPS,  # autonomous
    "D": Q.GPS_FIX_DGPS,  # differential
    "P": Q.GPS_FIX_PPS,  # precise
    "R": Q.GPS_FIX_RTK,  # RTK, integer ambiguities
    "F": Q.GPS_FIX_FLOAT_RTK,  # RTK, float ambiguities
    "E": Q.GPS_FIX_ESTIMATED,  # dead reckoning
    "M": Q.GPS_FIX_MANUAL,  # manual input
    "S": Q.GPS_FIX_SIMULATION,  # simulator
    "N": Q.GPS_FIX_INVALID,  # no fix
    "V": Q.GPS_FIX_INVALID,  # invalid (some receivers)
}
GOOD_QUALITIES = frozenset(
    {Q.GPS_FIX_GPS, Q.GPS_FIX_DGPS, Q.GPS_FIX_PPS, Q.GPS_FIX_RTK, Q.GPS_FIX_FLOAT_RTK}
)
NOT_REAL = frozenset({Q.GPS_FIX_ESTIMATED, Q.GPS_FIX_MANUAL, Q.GPS_FIX_SIMULATION})


class NmeaError(ValueError):
    """A sentence that is not good NMEA; `kind` is "checksum" or "malformed"."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def split_sentence(line: bytes) -> tuple[str, str, list[str]]:
    """The sentence's talker (`GP`), type (`GGA`) and fields, after checking the checksum.
    Proprietary sentences have no talker and the type `P` + maker + type. Anything before the
    last `$` (noise, a doubled `$`, the start of a sentence cut short) is not part of it."""
    text = line.strip()
    start = text.rfind(b"$")  # '$' is reserved: what is before the last one is not this sentence
    if start < 0:
        raise NmeaError("malformed", "no '$'")
    text = text[start:]
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
        return "", address, fields[1:]
    if len(address) != 5 or not address.isalnum():
        raise NmeaError("malformed", f"address {address!r}")
    return address[:2], address[2:], fields[1:]


# ---- fields -----------------------------------------------------------------------------------


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
    """`ddmm.mmmm` / `dddmm.mmmm` and N/S or E/W into signed degrees (NaN when empty).
    Receivers that drop a leading zero of the degrees (`734.04` for `00734.04`) are read too:
    the minutes are always the two digits before the decimal point."""
    if not value and not hemisphere:
        return NAN
    if hemisphere not in ("NS" if negative == "S" else "EW") or len(hemisphere) != 1:
        raise NmeaError("malformed", f"hemisphere {hemisphere!r}")
    whole = value.split(".")[0]
    if not 3 <= len(whole) <= degree_digits + 2 or not whole.isdigit():
        raise NmeaError("malformed", f"coordinate {value!r}")
    degrees = _number(whole[:-2])
    minutes = _number(value[len(whole) - 2 :])
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


def _day(year: int, month: int, day: int, text: str) -> float:
    try:
        return datetime(year, month, day, tzinfo=UTC).timestamp()
    except ValueError:
        raise NmeaError("malformed", f"date {text!r}") from None


def _rmc_date(text: str) -> float | None:
    """`ddmmyy` into seconds since the epoch at that day's midnight (None when empty); the
    two-digit year as the module says."""
    if not text:
        return None
    if len(text) != 6 or not text.isdigit():
        raise NmeaError("malformed", f"date {text!r}")
    yy = int(text[4:])
    return _day((1900 if yy >= 80 else 2000) + yy, int(text[2:4]), int(text[:2]), text)


def time_idl(seconds: float) -> Miro.TimeIDL:
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


# ---- sentences --------------------------------------------------------------------------------


@dataclass
class Sentence:
    """What one sentence says: reading fields to set, and what it tells about its epoch."""

    fields: dict[str, object] = field(default_factory=dict)
    time_of_day: float | None = None  # UTC time of the fix, for sentences that carry one
    date: float | None = None  # midnight of the fix's date (RMC, ZDA)
    position: bool = False  # carries a position (GGA, RMC, GNS, GLL), even an empty one
    fix: bool | None = None  # says there is a fix (True), there is none (False), or nothing
    quality: Miro.GpsFixQualityIDL | None = None  # says what kind of fix


def _says(s: Sentence, fix: bool, quality: Miro.GpsFixQualityIDL | None = None) -> Sentence:
    s.fix, s.quality = fix, quality
    return s


def _mode(s: Sentence, letters: str) -> Sentence:
    """What mode indicators say: one letter (RMC, GLL), or one per constellation (GNS: GPS,
    GLONASS, Galileo, BeiDou, QZSS, NavIC), where the fix is the best any of them has. An
    unknown letter, or none, says nothing."""
    qualities = [MODE_QUALITY[c] for c in letters if c in MODE_QUALITY]
    if qualities:
        good = [q for q in qualities if q in GOOD_QUALITIES]
        other = [q for q in qualities if q is not Q.GPS_FIX_INVALID]
        best = (good or other or qualities)[0]
        _says(s, best is not Q.GPS_FIX_INVALID, best)
    return s


def _position(lat: float, lon: float) -> dict[str, object]:
    return {"latitude": lat, "longitude": lon}


def gga(talker: str, f: list[str]) -> Sentence:
    if len(f) < 14:
        raise NmeaError("malformed", f"GGA has {len(f)} fields")
    s = Sentence(time_of_day=_time_of_day(f[0]), position=True)
    s.fields = _position(_angle(f[1], f[2], "S", 2), _angle(f[3], f[4], "W", 3))
    used = _integer(f[6], 99)
    s.fields.update(
        satellitesUsed=used,
        hdop=_number(f[7]),
        altitude=_number(f[8]),
        geoidSeparation=_number(f[10]),
        dgpsAge=_number(f[12]),
        dgpsStation=_integer(f[13], 1023),
    )
    if f[5]:
        quality = Q(_integer(f[5], 8))
        # Fewer than three satellites make no fix, whatever the quality says: some receivers
        # (Hemisphere) keep quality 1 and the last position with 0 satellites. Only for the
        # GPS and combined talkers: a receiver that sends one GGA per constellation (SiRFstarV)
        # may use few satellites of one.
        few = talker in ("GP", "GN") and used < 3
        _says(s, quality is not Q.GPS_FIX_INVALID and not few, quality)
    return s


def rmc(talker: str, f: list[str]) -> Sentence:
    if len(f) < 11:
        raise NmeaError("malformed", f"RMC has {len(f)} fields")
    if f[1] not in ("A", "V"):
        raise NmeaError("malformed", f"RMC status {f[1]!r}")
    s = Sentence(time_of_day=_time_of_day(f[0]), date=_rmc_date(f[8]), position=True)
    variation = _number(f[9])
    if f[10] == "W":
        variation = -variation
    s.fields = _position(_angle(f[2], f[3], "S", 2), _angle(f[4], f[5], "W", 3))
    s.fields.update(speed=_number(f[6]) * KNOT, course=_number(f[7]), magneticVariation=variation)
    if f[1] == "V":  # its date too: receivers without a fix send stale or made-up dates
        s.date = None
        return _says(s, False)
    _says(s, True, Q.GPS_FIX_GPS)
    return _mode(s, f[11][:1]) if len(f) > 11 else s


def gll(talker: str, f: list[str]) -> Sentence:
    if len(f) < 4:
        raise NmeaError("malformed", f"GLL has {len(f)} fields")
    s = Sentence(time_of_day=_time_of_day(f[4]) if len(f) > 4 else None, position=True)
    s.fields = _position(_angle(f[0], f[1], "S", 2), _angle(f[2], f[3], "W", 3))
    status = f[5] if len(f) > 5 else ""
    if status not in ("", "A", "V"):
        raise NmeaError("malformed", f"GLL status {status!r}")
    if status == "V":
        return _says(s, False)
    if status == "A":  # very old receivers send no status: that says nothing
        _says(s, True, Q.GPS_FIX_GPS)
    return _mode(s, f[6][:1]) if len(f) > 6 else s


def gns(talker: str, f: list[str]) -> Sentence:
    if len(f) < 12:
        raise NmeaError("malformed", f"GNS has {len(f)} fields")
    s = Sentence(time_of_day=_time_of_day(f[0]), position=True)
    s.fields = _position(_angle(f[1], f[2], "S", 2), _angle(f[3], f[4], "W", 3))
    s.fields.update(
        satellitesUsed=_integer(f[6], 99),
        hdop=_number(f[7]),
        altitude=_number(f[8]),
        geoidSeparation=_number(f[9]),
        dgpsAge=_number(f[10]),
        dgpsStation=_integer(f[11], 1023),
    )
    # NMEA 4.1's navigational status: S safe, C caution, U unsafe, V not provided. An unsafe
    # fix is not vouched for: the sentence says nothing about it.
    if len(f) > 12 and f[12] == "U":
        return s
    return _mode(s, f[5])


def vtg(talker: str, f: list[str]) -> Sentence:
    if len(f) < 8:
        raise NmeaError("malformed", f"VTG has {len(f)} fields")
    return Sentence({"course": _number(f[0]), "speed": _number(f[6]) / 3.6})


def gsa(talker: str, f: list[str]) -> Sentence:
    if len(f) < 17:
        raise NmeaError("malformed", f"GSA has {len(f)} fields")
    # Twelve PRN fields (24 on some 24-channel receivers), then PDOP, HDOP, VDOP, then NMEA
    # 4.10's system id or a maker's extra field.
    wide = len(f) >= 29
    prns, dops = (f[2:26], f[26:29]) if wide else (f[2:14], f[14:17])
    mode = Miro.GpsFixModeIDL(_integer(f[1], 3)) if f[1] != "E" else Miro.GpsFixModeIDL(0)
    s = Sentence(
        {
            "mode": mode,
            "satellites": [_integer(prn, 0xFFFF) for prn in prns if prn],
            "pdop": _number(dops[0]),
            "hdop": _number(dops[1]),
            "vdop": _number(dops[2]),
        }
    )
    if f[1] == "E":  # u-blox Antaris: dead reckoning
        return _says(s, True, Q.GPS_FIX_ESTIMATED)
    return _says(s, mode > 1) if mode else s


def zda(talker: str, f: list[str]) -> Sentence:
    if len(f) < 4:
        raise NmeaError("malformed", f"ZDA has {len(f)} fields")
    s = Sentence(time_of_day=_time_of_day(f[0]))
    if f[1] and f[2] and f[3]:
        text = ",".join(f[1:4])
        if not (f[1].isdigit() and f[2].isdigit() and len(f[3]) == 4 and f[3].isdigit()):
            raise NmeaError("malformed", f"date {text!r}")
        s.date = _day(int(f[3]), int(f[2]), int(f[1]), text)
    return s


def pgrmz(talker: str, f: list[str]) -> Sentence:
    """Garmin's altitude: `$PGRMZ,246,f,3` (feet, or `m` metres; then the fix dimension)."""
    if len(f) < 2:
        raise NmeaError("malformed", f"PGRMZ has {len(f)} fields")
    if f[1] not in ("f", "m", "F", "M", ""):
        raise NmeaError("malformed", f"PGRMZ unit {f[1]!r}")
    altitude = _number(f[0]) * (FOOT if f[1] in ("f", "F") else 1.0)
    return Sentence({"altitude": altitude} if math.isfinite(altitude) else {})


HANDLERS: dict[str, Callable[[str, list[str]], Sentence]] = {
    "GGA": gga,
    "RMC": rmc,
    "GLL": gll,
    "GNS": gns,
    "VTG": vtg,
    "GSA": gsa,
    "ZDA": zda,
    "PGRMZ": pgrmz,
}


def decode(line: bytes) -> tuple[str, list[str], Sentence | None]:
    """The sentence's type, its fields, and what it says (None for a type not read here)."""
    talker, kind, fields = split_sentence(line)
    handler = HANDLERS.get(kind)
    return kind, fields, handler(talker, fields) if handler is not None else None
