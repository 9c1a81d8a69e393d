"""The GPS driver's NMEA parsing: sentence fields, checksums and bad input (services/gps/nmea.py),
and one reading per fix with its validity and date (services/gps/nmea_epochs.py)."""

from __future__ import annotations

import math
import sys
from datetime import date
from functools import reduce

import Miro
from hypothesis import given
from hypothesis import strategies as st
from repo_paths import REPO

sys.path.insert(0, str(REPO))

from services.gps.nmea import Sentence, decode
from services.gps.nmea_epochs import NmeaParser

Q = Miro.GpsFixQualityIDL
DAY = 86400
MAR_23_1994 = 764380800  # 1994-03-23 00:00 UTC


def sentence(body: str) -> bytes:
    """`$body*CS\\r\\n` with the right checksum."""
    checksum = reduce(lambda a, c: a ^ ord(c), body, 0)
    return f"${body}*{checksum:02X}\r\n".encode()


def feed(parser: NmeaParser, *bodies: str, stamp: float = 0.0) -> list[Miro.GpsDataIDL]:
    out: list[Miro.GpsDataIDL] = []
    for body in bodies:
        out += parser.feed(sentence(body), stamp)
    return out


def epoch(t: str, lat: str = "4807.038", *, quality: int = 1, status: str = "A") -> list[str]:
    """The GGA, GSA and RMC of one fix at time `t` on 1994-03-23."""
    return [
        f"GPGGA,{t},{lat},N,01131.000,E,{quality},08,0.9,545.4,M,46.9,M,,",
        "GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1",
        f"GPRMC,{t},{status},{lat},N,01131.000,E,022.4,084.4,230394,003.1,W",
    ]


GGA = "GPGGA,123519.50,4807.038,N,01131.000,E,2,08,0.9,545.4,M,46.9,M,3.2,0123"
RMC = "GPRMC,123519.50,A,4807.040,S,01131.002,W,022.4,084.4,230394,003.1,W"


def said(body: str) -> Sentence:
    """What one sentence says (services/gps/nmea.py alone)."""
    kind, _, s = decode(sentence(body))
    assert s is not None, kind
    return s


def test_what_each_sentence_says() -> None:
    gga = said(GGA)
    assert gga.time_of_day == 12 * 3600 + 35 * 60 + 19.5 and gga.position
    assert (gga.fix, gga.quality) == (True, Q.GPS_FIX_DGPS)
    assert math.isclose(gga.fields["latitude"], 48 + 7.038 / 60)  # type: ignore[arg-type]
    assert (gga.fields["satellitesUsed"], gga.fields["dgpsStation"]) == (8, 123)
    rmc = said(RMC)
    assert rmc.date == MAR_23_1994 and (rmc.fix, rmc.quality) == (True, Q.GPS_FIX_GPS)
    assert rmc.fields["latitude"] < 0 and rmc.fields["longitude"] < 0  # type: ignore[operator]
    gll = said("GPGLL,4916.45,N,12311.12,W,225444,A,D")
    assert (gll.time_of_day, gll.fix, gll.quality) == (82484, True, Q.GPS_FIX_DGPS)
    assert said("GPGLL,4916.45,N,12311.12,W,225444,V,N").fix is False
    assert said("GPGLL,4916.45,N,12311.12,W").fix is None  # NMEA 1.5: no status, says nothing
    gns = said(
        "GNGNS,224749.00,3333.4268304,N,11153.3538273,W,NDD,19,0.6,406.110,-26.294,6.0,0138,S"
    )
    assert (gns.fix, gns.quality) == (True, Q.GPS_FIX_DGPS)  # GLONASS and Galileo: differential
    assert gns.fields["altitude"] == 406.11 and gns.fields["satellitesUsed"] == 19
    assert said("GNGNS,224749.00,,,,,NNNN,00,,,,,,V").fix is False
    assert said("GNGNS,224749.00,3333.42,N,11153.35,W,AA,19,0.6,406.1,-26.2,,,U").fix is None
    assert (
        said("GPGSA,A,1,,,,,,,,,,,,,,,").fix is False
        and said("GPGSA,A,3,04,,,,,,,,,,,,2.5,1.3,2.1").fix
    )
    assert said("GPZDA,160012.71,11,03,2004,-1,00").date == 1078963200  # 2004-03-11
    assert math.isclose(said("PGRMZ,246,f,3").fields["altitude"], 246 * 0.3048)  # type: ignore[arg-type]
    for body, quality in (
        ("GPGGA,1,4807.038,N,01131.000,E,6,08,0.9,545.4,M,46.9,M,,", Q.GPS_FIX_ESTIMATED),
        ("GPRMC,1,A,4807.04,S,01131.00,W,0,0,230394,,,M", Q.GPS_FIX_MANUAL),
        ("GPGGA,1,4807.038,N,01131.000,E,8,08,0.9,545.4,M,46.9,M,,", Q.GPS_FIX_SIMULATION),
    ):
        assert said(body.replace(",1,", ",120000,", 1)).quality is quality


def test_the_sentences_of_one_fix_make_one_reading_with_all_their_fields() -> None:
    parser = NmeaParser()
    vtg = "GPVTG,054.7,T,034.4,M,005.5,N,010.2,K"
    assert feed(parser, GGA, "GNGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1", RMC, vtg) == []
    [r] = parser.flush()  # the receiver fell silent: the fix is complete
    assert parser.flush() == []  # one reading a fix
    assert r.utcTime == Miro.TimeIDL(MAR_23_1994 + 12 * 3600 + 35 * 60 + 19, 500000)
    assert math.isclose(r.latitude, -(48 + 7.040 / 60)) and r.longitude < 0  # the last one's
    assert r.quality is Q.GPS_FIX_DGPS and r.valid  # GGA's quality
    assert (r.satellitesUsed, r.altitude, r.dgpsStation) == (8, 545.4, 123)
    assert math.isclose(r.dgpsAge, 3.2, rel_tol=1e-6)
    assert r.mode is Miro.GpsFixModeIDL.GPS_MODE_3D and r.satellites == [4, 5, 9, 12, 24]
    assert math.isclose(r.magneticVariation, -3.1, rel_tol=1e-6)
    # The fix as it was when it was reported, at the RMC (no cycle end known yet: at every
    # sentence with a position); the VTG after it goes with the next fix.
    assert math.isclose(r.speed, 22.4 * 1852 / 3600, rel_tol=1e-6)
    assert parser.counts.good == 4


def test_each_fix_goes_out_once_complete() -> None:
    parser = NmeaParser()
    readings = [feed(parser, body) for second in range(5) for body in epoch(f"1235{second:02d}")]
    # A fix goes out when the next one starts (at its GGA), or when the receiver falls silent.
    assert [len(r) for r in readings] == [0, 0, 0] + [1, 0, 0] * 4
    [last] = parser.flush()
    times = [r[0].utcTime.sec % DAY for r in readings if r] + [last.utcTime.sec % DAY]
    assert times == [12 * 3600 + 35 * 60 + s for s in range(5)]
    assert all(r[0].valid for r in readings if r) and last.valid
    # A cycle cut short before its end (the RMC, learnt from the first epochs) is no fix.
    feed(parser, *epoch("123505")[:2])
    [cut, whole] = feed(parser, *epoch("123506")) + parser.flush()
    assert not cut.valid and cut.utcTime.sec % DAY == 12 * 3600 + 35 * 60 + 5
    assert whole.valid and whole.utcTime.sec % DAY == 12 * 3600 + 35 * 60 + 6


def test_a_repeated_time_is_the_same_fix_not_a_new_reading() -> None:
    parser = NmeaParser()
    out = feed(parser, *epoch("123500"), *epoch("123501"), *epoch("123501"), *epoch("123502"))
    assert [r.utcTime.sec % 60 for r in out + parser.flush()] == [0, 1, 2]


def test_gll_and_gns_receivers() -> None:
    old, gnss = NmeaParser(), NmeaParser()
    out: list[Miro.GpsDataIDL] = []
    for second in range(3):  # an old receiver: GLL and ZDA only
        t = f"12010{second}.00"
        gll = f"GPGLL,4807.10{second},N,01131.000,E,{t},A,A"
        out += feed(old, f"GPZDA,{t},14,03,2025,00,00", gll)
    for second in range(3):  # a GNSS receiver: GNS, one GSA per constellation
        t = f"12011{second}.00"
        out += feed(
            gnss,
            f"GNRMC,{t},A,3342.0500,S,15112.0300,E,0.5,12.0,140325,,,A,S",
            f"GNGNS,{t},3342.0500,S,15112.0300,E,NAAN,14,0.8,41.2,22.3,,,S",
            "GPGSA,A,3,05,12,,,,,,,,,,,1.6,0.8,1.4",
            "BDGSA,A,3,214,,,,,,,,,,,,1.6,0.8,1.4",
        )
    out += old.flush() + gnss.flush()
    assert [r.valid for r in out] == [True] * 6
    assert out[0].utcTime.sec == 1741953660  # 2025-03-14 12:01:00
    assert math.isclose(out[-1].latitude, -(33 + 42.05 / 60))
    assert out[-1].quality is Q.GPS_FIX_GPS and out[-1].altitude == 41.2
    assert out[-1].satellites == [5, 12, 214]  # one GSA per constellation, added up


def test_demo_mode_dead_reckoning_and_manual_input_are_no_fixes() -> None:
    parser = NmeaParser()
    demo = [
        "GPRMC,{t},V,3854.5087,N,07726.4523,W,0.0,0.0,051025,10.5,W,S",
        "GPGGA,{t},3854.5087,N,07726.4523,W,8,10,2.0,268.8,M,-33.9,M,,",
        "GPGSA,A,3,03,07,08,11,13,16,19,23,24,28,,,3.6,2.0,3.0",
    ]
    out = []
    for second in range(4):
        out += feed(parser, *(b.format(t=f"22150{second}") for b in demo))
    out += feed(
        parser,
        "GPRMC,221510,A,3854.5087,N,07726.4523,W,12.0,90.0,051025,10.5,W,E",  # dead reckoning
        "GPRMC,221511,A,3854.5087,N,07726.4523,W,12.0,90.0,051025,10.5,W,E",
        "GPRMC,221520,A,3854.5087,N,07726.4523,W,0.0,0.0,051025,10.5,W,M",  # manual input
    )
    out += parser.flush()
    assert not any(r.valid for r in out)
    assert [r.quality for r in out] == [Q.GPS_FIX_SIMULATION] * 4 + [Q.GPS_FIX_ESTIMATED] * 2 + [
        Q.GPS_FIX_MANUAL
    ]


def test_a_fix_needs_three_satellites_and_a_fix_quality() -> None:
    parser = NmeaParser()
    out = feed(
        parser,
        "GPRMC,120000,A,4807.038,N,01131.000,E,0.0,0.0,010125,,,A",  # the date
        "GPGGA,120001,4807.038,N,01131.000,E,1,00,3.3,10.8,M,-33.3,M,,",  # Hemisphere's stale
        "GPGGA,120002,4807.038,N,01131.000,E,0,08,0.9,545.4,M,46.9,M,,",
        "GPGGA,120003,,,,,1,08,0.9,545.4,M,46.9,M,,",  # no position
        "GPGGA,120004,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    )
    out += parser.flush()
    assert [r.valid for r in out] == [True, False, False, False, True]
    assert math.isnan(out[3].latitude)


def test_two_digit_years_and_midnight() -> None:
    parser = NmeaParser()
    out = feed(
        parser,
        "GPRMC,235959,A,4527.458,S,16709.165,E,0.0,94.5,311299,024.1,E",
        "GPGGA,000000,4527.458,S,16709.165,E,1,05,2.1,14.7,M,1.1,M,,",  # before its RMC
        "GPRMC,000000,A,4527.458,S,16709.165,E,0.0,94.5,010100,024.1,E",
        "GPRMC,120000,A,4527.458,S,16709.165,E,0.0,94.5,010180,024.1,E",
        "GPRMC,120001,A,4527.458,S,16709.165,E,0.0,94.5,010179,024.1,E",
    )
    out += parser.flush()
    years = [date.fromtimestamp(r.utcTime.sec).year for r in out]
    assert [r.utcTime.sec % DAY for r in out[:2]] == [DAY - 1, 0]
    assert years[1:] == [2000, 1980, 2079]
    assert out[1].utcTime.sec == 946684800  # 2000-01-01, the GGA's day found from the time


def test_the_week_rollover_is_corrected_when_asked() -> None:
    early = "GPRMC,120000,A,5123.400,N,00012.340,W,0.1,0.0,210805,,,A"  # 1024 weeks too early
    parser = NmeaParser()
    [plain] = feed(parser, early) + parser.flush()
    assert plain.utcTime.sec == 1743940800 - 1024 * 7 * DAY  # as the receiver said
    parser = NmeaParser(date_not_before=date(2020, 1, 1))
    [fixed] = feed(parser, early) + parser.flush()
    assert fixed.utcTime.sec == 1743940800  # 2025-04-06 12:00
    assert parser.rollovers == 1


def test_without_a_date_no_fix_unless_the_host_clock_gives_it() -> None:
    gga = "GPGGA,120001,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
    parser = NmeaParser()
    [r] = feed(parser, gga) + parser.flush()
    assert not r.valid and r.utcTime.sec == 12 * 3600 + 1  # the time of day only
    parser = NmeaParser(host_date=True)
    midnight = 1741910400  # 2025-03-14
    host = midnight + 12 * 3600 + 3.0  # two seconds after the fix
    [r] = feed(parser, gga, stamp=host) + parser.flush()
    assert r.valid and r.utcTime.sec == midnight + 12 * 3600 + 1
    [r] = feed(parser, gga.replace("120001", "235959"), stamp=midnight + 2.0) + parser.flush()
    assert r.utcTime.sec == midnight - 1  # a fix just before midnight, seen just after


def test_pgrmz_gives_the_altitude_when_no_gga_does() -> None:
    parser = NmeaParser()
    feed(
        parser,
        "GPRMC,120000,A,4527.458,S,16709.165,E,0.0,94.5,010125,024.1,E",
        "GPGLL,4527.458,S,16709.165,E,120000,A",
        "PGRMZ,48,f,3",
    )
    [r] = parser.flush()
    assert math.isclose(r.altitude, 48 * 0.3048) and r.valid
    feed(
        parser,
        "GPRMC,120001,A,4527.458,S,16709.165,E,0.0,94.5,010125,024.1,E",
        "GPGGA,120001,4527.458,S,16709.165,E,1,05,2.1,14.7,M,1.1,M,,",
        "GPGLL,4527.458,S,16709.165,E,120001,A",
        "PGRMZ,48,f,3",
    )
    [r] = parser.flush()
    assert r.altitude == 14.7  # GGA's, in metres to a decimetre, not PGRMZ's whole feet


def test_bad_sentences_are_counted_and_change_nothing() -> None:
    parser = NmeaParser()
    feed(parser, GGA)
    [good] = parser.flush()
    bad = [
        sentence(GGA).replace(b"*", b"0*"),  # wrong checksum
        sentence(GGA)[:-5] + b"\r\n",  # no checksum
        sentence("GPGGA,123519,48x7.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
        sentence("GPGGA,123519,4807.038,Q,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
        sentence("GPGGA,1235"),
        sentence("GPRMC,123520,X,4807.040,S,01131.002,W,022.4,084.4,230394,003.1,W"),
        sentence("GPRMC,123520,A,4807.040,S,01131.002,W,022.4,084.4,320394,003.1,W"),
        b"$GPGGA,\xff\xfe*00\r\n",
        b"line noise\r\n",
    ]
    for line in bad:
        assert parser.feed(line, 2.0) == []
    assert parser.feed(sentence("GPGSV,3,1,11,03,03,111,00"), 2.0) == []
    assert parser.feed(sentence("PGRME,15.0,M,45.0,M,25.0,M"), 2.0) == []
    assert (parser.counts.checksum, parser.counts.malformed, parser.counts.ignored) == (3, 6, 2)
    [again] = feed(parser, GGA.replace("123519.50", "123520.50")) + parser.flush()
    assert again.latitude == good.latitude and again.altitude == good.altitude


def test_noise_and_a_doubled_dollar_before_a_sentence_are_not_part_of_it() -> None:
    parser = NmeaParser()
    assert parser.feed(b"\x00\xff$GPGG$" + sentence(GGA), 1.0) == []
    assert parser.feed(b"$" + sentence(RMC), 1.0) == []
    assert parser.counts.good == 2 and parser.counts.checksum == 0


def test_an_empty_fix_is_nan_not_zero() -> None:
    parser = NmeaParser()
    feed(parser, "GPGGA,120000,,,,,0,00,,,M,,M,,")
    [r] = parser.flush()
    assert not r.valid and r.quality is Q.GPS_FIX_INVALID
    assert math.isnan(r.latitude) and math.isnan(r.longitude) and math.isnan(r.altitude)


@given(st.binary(max_size=120))
def test_no_input_makes_the_parser_raise(data: bytes) -> None:
    parser = NmeaParser()
    parser.feed(data, 0.0)
    parser.feed(b"$GPGGA," + data, 0.0)
    for kind in ("GPRMC", "GNGNS", "GPGLL", "GPZDA", "GPGSA", "PGRMZ"):
        body = kind + "," + data.decode("latin-1")
        checksum = reduce(lambda a, c: a ^ c, body.encode("latin-1"), 0)
        parser.feed(b"$" + body.encode("latin-1") + b"*%02X" % checksum, 0.0)
    parser.flush()
