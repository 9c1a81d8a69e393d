"""The GPS driver against captures, fix by fix: our synthesised ones (tests/data/nmea: GLL, GNS,
demo mode, week rollover, two-digit years, $PGRMZ), always; real receivers' logs with gpsd's
decoding of them (tests/nmea_captures.py says where they are fetched to), when present.

Each capture goes through the parser in this process (every log, quickly), and a few through a
pseudo-terminal into the driver process, whose published readings are compared the same way.
bench/gps_captures.py replays every real log through the driver and prints the agreement."""

from __future__ import annotations

import math
import sys
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
from device_rig import GpsRig
from nmea_captures import (
    OurCapture,
    compare,
    data_lines,
    gpsd_fixes,
    gpsd_logs,
    iso,
    our_captures,
    valid_fixes,
)
from repo_paths import REPO

sys.path.insert(0, str(REPO))

from services.gps.nmea_epochs import NmeaParser, parse_date

# Real logs where the driver knowingly gives other fixes than gpsd, and why.
DIFFERENT = {
    "ericsson-gru04-02-70sec.log": "in two epochs gpsd takes the position of a proprietary "
    "sentence (Trimble's PERC)",
}


def parse(lines: list[bytes], **options: str) -> list[Miro.GpsDataIDL]:
    parser = NmeaParser(date_not_before=parse_date(options.get("date_not_before", "")))
    out: list[Miro.GpsDataIDL] = []
    for line in lines:
        out += parser.feed(line, 0.0)
    return out + parser.flush()


@pytest.mark.parametrize("capture", our_captures(), ids=lambda c: c.path.name)
def test_our_captures(capture: OurCapture) -> None:
    readings = parse(data_lines(capture.path), **capture.options)
    result = compare(capture.fixes, valid_fixes(readings))
    assert result.agree, result
    altitudes = {iso(r.utcTime): r.altitude for r in readings if r.valid}
    for time, altitude in capture.altitudes.items():
        assert math.isclose(altitudes[time], altitude, abs_tol=1e-3), time
    assert all(r.utcTime.sec > 0 for r in readings)


def real_logs() -> list[object]:
    logs = gpsd_logs()
    if not logs:
        reason = "no real receiver logs: fetch gpsd's test/daemon into ../shared/captures/gpsd"
        return [pytest.param(None, marks=pytest.mark.skip(reason=reason), id="gpsd-logs")]
    params = []
    for log in logs:
        marks = [pytest.mark.xfail(reason=DIFFERENT[log.name])] if log.name in DIFFERENT else []
        params.append(pytest.param(log, id=log.name, marks=marks))
    return params


@pytest.mark.parametrize("log", real_logs())
def test_real_receiver_logs_give_gpsds_fixes(log: Path) -> None:
    result = compare(gpsd_fixes(log), valid_fixes(parse(data_lines(log))))
    assert result.agree, result


@pytest.fixture
def rig(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[GpsRig]:
    parameters: dict[str, str] = getattr(request, "param", {})
    r = GpsRig(tmp_path, **parameters)
    try:
        yield r
    finally:
        r.close()


def through_the_driver(rig: GpsRig, lines: list[bytes]) -> list[Miro.GpsDataIDL]:
    rig.replay(lines)
    summary = rig.close()  # once all it published has arrived
    readings = rig.readings()
    assert rig.events.missed == 0
    assert f"{len(readings)} readings, {len(readings)} published" in summary, summary
    return readings


CAPTURES = {c.path.name: c for c in our_captures()}


@pytest.mark.parametrize(
    ("rig", "name"),
    [
        ({}, "gns-multi.nmea"),
        ({}, "demo-mode.nmea"),
        ({"DateNotBefore": "2020-01-01"}, "rollover.nmea"),
    ],
    indirect=["rig"],
    ids=["gns", "demo", "rollover"],
)
def test_our_captures_through_the_driver(rig: GpsRig, name: str) -> None:
    capture = CAPTURES[name]
    readings = through_the_driver(rig, data_lines(capture.path))
    result = compare(capture.fixes, valid_fixes(readings))
    assert result.agree, result
    times = [r.utcTime.sec for r in readings]
    assert len(times) == len(set(times)), "one reading per fix"


REPLAYED = ["GPSmap-76S.log", "quectel-eg25-g-2.log", "ublox-zed-f9p-nmea.log"]


def replayed_logs() -> list[object]:
    logs = {log.name: log for log in gpsd_logs()}
    if not logs:
        return [pytest.param(None, marks=pytest.mark.skip(reason="no real receiver logs"))]
    return [pytest.param(logs.get(name), id=name) for name in REPLAYED]


@pytest.mark.parametrize("log", replayed_logs())
def test_real_logs_through_the_driver(rig: GpsRig, log: Path | None) -> None:
    if log is None:
        pytest.skip("this log is not among the fetched captures")
    readings = through_the_driver(rig, data_lines(log))
    result = compare(gpsd_fixes(log), valid_fixes(readings))
    assert result.agree, result
