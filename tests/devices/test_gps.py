"""The GPS driver as a process, against a pseudo-terminal fed NMEA with corrupt lines, split
writes and a receiver that vanishes and comes back: every fix arrives as one event and through
polling, and the driver's counts of bad sentences are right."""

from __future__ import annotations

import itertools
import math
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
from device_rig import GPS, Driver, GpsRig
from loopback import NamingProcess, Recorder, eventually, service_env

from miro_gen import Client
from miro_gen.sim.nmea import Fix, checksummed, sentences, synthetic_fixes
from miro_gen.sim.pty_device import PtyDevice


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[tuple[PtyDevice, Driver, Recorder, Miro.Gps]]:
    rig = GpsRig(tmp_path)
    client = Client(["t", "--naming", rig.naming.endpoint])
    try:
        yield rig.device, rig.driver, rig.events, client.resolve_name("rover/Gps", Miro.Gps)
    finally:
        client.close()
        rig.close()


def test_the_driver_against_a_pseudo_terminal(
    rig: tuple[PtyDevice, Driver, Recorder, Miro.Gps],
) -> None:
    device, driver, events, gps = rig
    fixes: Iterator[Fix] = synthetic_fixes(1.7e9, rate=10, seed=7)
    epochs = 0

    def send(fix: Fix, pieces: int = 1) -> None:
        nonlocal epochs
        data = b"".join(sentences(fix))
        step = math.ceil(len(data) / pieces)
        for at in range(0, len(data), step):
            device.write(data[at : at + step])
            time.sleep(0.002)
        epochs += 1

    eventually(lambda: driver.logged("receiver connected") == 1)
    while not events.events:  # the subscription travels to the driver meanwhile
        send(next(fixes))
        time.sleep(0.1)
    eventually(lambda: len(events.events) == epochs)  # one reading per fix
    settled = len(events.events)

    # Ten epochs written in pieces, with bad sentences and noise among them.
    bad = [
        checksummed("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")[:-5]
        + b"*00\r\n",
        b"$GPRMC,123520,A,4807.040,S,01131.002,W,022.4,084.4,230394,003.1,W*11\r\n",
        checksummed("GPGGA,12x519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
        checksummed("GPGSV,3,1,11,03,03,111,00,04,15,270,00"),
        b"line noise\r\n",
    ]
    sent: list[Fix] = []
    for n in range(10):
        sent.append(next(fixes))
        send(sent[-1], pieces=1 + n % 4)
        if n < len(bad):
            device.write(bad[n])
    eventually(lambda: len(events.events) == settled + 10)
    assert events.missed == 0
    last = events.events[-1].payload
    assert isinstance(last, Miro.GpsDataIDL)
    assert math.isclose(last.latitude, sent[-1].latitude, abs_tol=2e-6)
    assert math.isclose(last.longitude, sent[-1].longitude, abs_tol=2e-6)

    # Polling: the latest reading, then the next one.
    assert math.isclose(gps.getData().latitude, sent[-1].latitude, abs_tol=2e-6)
    waited: list[Miro.GpsDataIDL] = []
    caller = threading.Thread(target=lambda: waited.append(gps.getWaitData()))
    caller.start()
    later: list[Fix] = []
    while caller.is_alive() and len(later) < 50:
        time.sleep(0.1)
        later.append(next(fixes))
        send(later[-1])
    caller.join(5)
    assert waited and any(math.isclose(waited[0].latitude, f.latitude, abs_tol=2e-6) for f in later)
    eventually(lambda: len(events.events) == epochs)

    # The receiver goes away and comes back.
    device.vanish()
    eventually(lambda: driver.logged("receiver lost") == 1)
    with pytest.raises(Miro.ETimeOut):
        gps.getWaitData()
    device.appear()
    eventually(lambda: driver.logged("receiver connected") == 2)
    before = len(events.events)
    for fix in itertools.islice(fixes, 3):
        send(fix, pieces=3)
    eventually(lambda: len(events.events) == before + 3)
    assert events.missed == 0

    summary = driver.stop()
    assert (
        f"gps: {4 * epochs} sentences used, 1 ignored, 2 with a bad checksum, 1 malformed, "
        in summary
    ), summary
    assert f"{epochs} readings, {epochs} published" in summary


def test_the_first_fix_after_timeless_no_fix_sentences_is_published(tmp_path: Path) -> None:
    """A 1 Hz receiver acquiring satellites sends a GGA with neither time nor fix each second,
    then gets its first fix. gpsd 3.22, fed this through a pseudo-terminal, reports a no-fix
    TPV (mode 1) for each of the three, then the fixes of 12:00:01, :02 and :03; so does the
    driver (each no-fix one goes out after the quarter second of silence that follows it)."""
    rig = GpsRig(tmp_path)
    try:
        readings = rig.readings
        for n in range(1, 4):
            rig.device.write(checksummed("GPGGA,,,,,,0,00,99.99,,,,,,"))
            eventually(lambda n=n: len(readings()) == n, 30)  # a second's pause at least
            time.sleep(0.5)
        for k in range(1, 4):
            time_of_day = f"12000{k}.00"
            rig.device.write(
                checksummed(f"GPGGA,{time_of_day},4807.038,N,01131.00{k},E,1,08,0.9,545.4,M,,M,,")
                + checksummed(f"GPRMC,{time_of_day},A,4807.038,N,01131.00{k},E,0.0,0.0,230394,,,A")
            )
            time.sleep(1.0)
        eventually(lambda: any(r.utcTime.sec % 60 == 3 for r in readings()), 30)
        got = [(r.valid, r.utcTime.sec % 60 if r.valid else None) for r in readings()]
        assert got == [(False, None)] * 3 + [(True, 1), (True, 2), (True, 3)]
    finally:
        rig.close()


def test_a_wrong_parameter_document_stops_the_driver_with_its_line(tmp_path: Path) -> None:
    config = tmp_path / "rover.xml"
    config.write_text(
        '<config><section name="Gps"><parameter name="Gps">\n'
        '  <parameter name="Baud" value="9600"/>\n'
        "</parameter></section></config>\n"
    )
    naming = NamingProcess()
    try:
        done = subprocess.run(
            [sys.executable, str(GPS), "-MCF", str(config), "--naming", naming.endpoint],
            capture_output=True,
            text=True,
            env=service_env(),
            timeout=30,
        )
    finally:
        naming.stop()
    assert done.returncode == 1
    assert f"{config}:2:" in done.stderr and "Baud" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_miro_sim_replays_the_shipped_recording(tmp_path: Path) -> None:
    import os
    import select

    sys.path.insert(0, str(GPS.parents[1]))
    from services.gps.nmea_epochs import NmeaParser

    link = tmp_path / "gps0"
    sim = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "sim", "nmea", "--file",
         str(GPS / "data" / "drive.nmea"), "--speedup", "20", "--link", str(link)],
        stdout=subprocess.PIPE,
        text=True,
        env=service_env(),
    )  # fmt: skip
    try:
        assert sim.stdout is not None
        assert sim.stdout.readline().startswith(f"NMEA on {link}")
        fd = os.open(link, os.O_RDONLY | os.O_NOCTTY)
        # Twenty epochs, one reading each, however long a loaded machine takes to send them
        # (the first line may be cut: it is left out).
        parser, pending, readings, first = NmeaParser(), b"", 0, True
        end = time.monotonic() + 30
        while readings < 20 and time.monotonic() < end and select.select([fd], [], [], 5)[0]:
            lines = (pending + os.read(fd, 4096)).splitlines(keepends=True)
            pending = lines.pop() if lines and not lines[-1].endswith(b"\n") else b""
            if first and lines:
                lines, first = lines[1:], False
            readings += sum(len(parser.feed(line, 0.0)) for line in lines)
        os.close(fd)
        assert readings >= 20
        assert parser.counts.checksum == parser.counts.malformed == 0
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(10)
    assert not link.exists()  # the simulator cleans up its link


def test_the_shipped_recording_of_the_drivers_events_decodes() -> None:
    from mcap.reader import make_reader

    with (GPS / "data" / "drive.mcap").open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.name for s in summary.schemas.values()}
        assert schemas == {"Miro::GpsDataIDL"}
        fixes = [Miro.GpsDataIDL.deserialize(m.data) for _, _, m in reader.iter_messages()]
    assert len(fixes) >= 100
    assert all(f.valid and 45.38 < f.latitude < 45.39 for f in fixes)
    times = [(f.utcTime.sec, f.utcTime.usec) for f in fixes]
    assert times == sorted(set(times)), "one event per fix"
