"""The GPS driver's NMEA parser: the fields of GGA, RMC, VTG and GSA, checksums, bad input."""

from __future__ import annotations

import math
import sys
from functools import reduce
from pathlib import Path

import Miro
from hypothesis import given
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services" / "gps"))
from nmea import NmeaParser


def sentence(body: str) -> bytes:
    """`$body*CS\\r\\n` with the right checksum."""
    checksum = reduce(lambda a, c: a ^ ord(c), body, 0)
    return f"${body}*{checksum:02X}\r\n".encode()


GGA = sentence("GPGGA,123519.50,4807.038,N,01131.000,E,2,08,0.9,545.4,M,46.9,M,3.2,0123")
RMC = sentence("GPRMC,123520,A,4807.040,S,01131.002,W,022.4,084.4,230394,003.1,W")
VTG = sentence("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K")
GSA = sentence("GNGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1")


def test_gga_gives_a_reading_with_its_fields() -> None:
    parser = NmeaParser()
    r = parser.feed(GGA, 1000.25)
    assert r is not None
    assert r.time == Miro.TimeIDL(1000, 250000)
    assert r.utcTime == Miro.TimeIDL(12 * 3600 + 35 * 60 + 19, 500000)  # no date yet
    assert math.isclose(r.latitude, 48 + 7.038 / 60)
    assert math.isclose(r.longitude, 11 + 31 / 60)
    assert r.quality is Miro.GpsFixQualityIDL.GPS_FIX_DGPS and r.valid
    assert (r.satellitesUsed, r.altitude, r.dgpsStation) == (8, 545.4, 123)
    assert math.isclose(r.hdop, 0.9, rel_tol=1e-6) and math.isclose(r.dgpsAge, 3.2, rel_tol=1e-6)
    assert math.isnan(r.speed) and math.isnan(r.pdop)  # not received yet


def test_rmc_vtg_gsa_and_the_date() -> None:
    parser = NmeaParser()
    assert parser.feed(GSA, 1.0) is None  # updates, completes nothing
    assert parser.feed(VTG, 1.0) is None
    r = parser.feed(RMC, 2.0)
    assert r is not None
    assert r.utcTime.sec == 764380800 + 12 * 3600 + 35 * 60 + 20  # 1994-03-23 12:35:20 UTC
    assert r.latitude < 0 and r.longitude < 0
    assert math.isclose(r.speed, 22.4 * 1852 / 3600, rel_tol=1e-6)
    assert math.isclose(r.magneticVariation, -3.1, rel_tol=1e-6)
    assert r.mode is Miro.GpsFixModeIDL.GPS_MODE_3D and r.satellites == [4, 5, 9, 12, 24]
    assert math.isclose(r.vdop, 2.1, rel_tol=1e-6)
    gga = parser.feed(GGA, 3.0)  # a GGA after the RMC: its time of day on the RMC's date
    assert gga is not None and gga.utcTime.sec == 764380800 + 12 * 3600 + 35 * 60 + 19
    assert math.isclose(gga.speed, 22.4 * 1852 / 3600, rel_tol=1e-6)  # kept from the RMC
    assert parser.counts.good == 4


def test_bad_sentences_are_counted_and_change_nothing() -> None:
    parser = NmeaParser()
    good = parser.feed(GGA, 1.0)
    bad = [
        GGA.replace(b"*", b"0*"),  # wrong checksum
        GGA[:-5] + b"\r\n",  # no checksum
        sentence("GPGGA,123519,48x7.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
        sentence("GPGGA,123519,4807.038,Q,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
        sentence("GPGGA,1235"),
        sentence("GPRMC,123520,X,4807.040,S,01131.002,W,022.4,084.4,230394,003.1,W"),
        sentence("GPRMC,123520,A,4807.040,S,01131.002,W,022.4,084.4,320394,003.1,W"),
        b"$GPGGA,\xff\xfe*00\r\n",
    ]
    for line in bad:
        assert parser.feed(line, 2.0) is None
    assert parser.feed(sentence("GPGSV,3,1,11,03,03,111,00"), 2.0) is None
    assert parser.feed(sentence("PGRME,15.0,M,45.0,M,25.0,M"), 2.0) is None
    assert (parser.counts.checksum, parser.counts.malformed, parser.counts.ignored) == (3, 5, 2)
    again = parser.feed(GGA, 3.0)
    assert again is not None and good is not None
    assert again.latitude == good.latitude and again.altitude == good.altitude


def test_an_empty_fix_is_nan_not_zero() -> None:
    r = NmeaParser().feed(sentence("GPGGA,,,,,,0,00,,,M,,M,,"), 1.0)
    assert r is not None and not r.valid
    assert math.isnan(r.latitude) and math.isnan(r.longitude) and math.isnan(r.altitude)


@given(st.binary(max_size=120))
def test_no_input_makes_the_parser_raise(data: bytes) -> None:
    parser = NmeaParser()
    parser.feed(data, 0.0)
    parser.feed(b"$GPGGA," + data, 0.0)
    body = "GPRMC," + data.decode("latin-1")
    checksum = reduce(lambda a, c: a ^ c, body.encode("latin-1"), 0)
    parser.feed(b"$" + body.encode("latin-1") + b"*%02X" % checksum, 0.0)
