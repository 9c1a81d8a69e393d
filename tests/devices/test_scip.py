"""SCIP 2.0 (miro_gen.devices.scip) and the simulated scanner (miro_gen.sim.scip): encodings,
checksums, responses, and the device's answers to each command."""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from loopback import service_env

from miro_gen.devices import scip
from miro_gen.devices.framers import LineFramer
from miro_gen.devices.scip import URG_04LX, ScanCommand, ScipError
from miro_gen.sim.scip import Faults, RecordedScene, RoomScene, ScipDevice


def test_checksums_and_encodings_as_the_specification_gives_them() -> None:
    assert scip.with_sum(b"00") == b"00P" and scip.with_sum(b"99") == b"99b"
    assert scip.encode(1234, 2) == b"CB" and scip.decode(b"1Dh") == 5432  # the manual's examples
    assert scip.encode(4095, 2) == b"oo" and scip.encode(5432, 3) == b"1Dh"
    with pytest.raises(ValueError):
        scip.encode(4096, 2)
    with pytest.raises(ScipError):
        scip.decode(b"0 a")


@given(st.integers(0, (1 << 18) - 1))
def test_three_characters_hold_any_18_bit_value(value: int) -> None:
    assert scip.decode(scip.encode(value, 3)) == value


def test_scan_commands_and_their_echoes() -> None:
    md = ScanCommand(44, 725, 1, 3, True, 0, 0)
    assert md.command() == b"MD0044072501000\n" and md.values == 682
    assert md.echo(remaining=7) == b"MD0044072501007"
    gs = ScanCommand(100, 200, 3, 2, False)
    assert gs.echo() == b"GS0100020003" and gs.values == 34
    assert ScanCommand.parse(b"MS0000108002123") == ScanCommand(0, 1080, 2, 2, True, 1, 23)
    for bad in (b"XX0044072501", b"GD004407250", b"MD00440725010"):
        with pytest.raises(ScipError):
            ScanCommand.parse(bad)
    with pytest.raises(ValueError):
        ScanCommand(10, 5)


def test_a_scan_split_over_lines_decodes_whole() -> None:
    values = list(range(0, 4000, 37))  # 109 values: 327 characters, six lines
    command = ScanCommand(0, len(values) - 1, continuous=False)
    frame = scip.response(command.echo(), "00", scip.scan_lines(1234, values, 3))
    assert frame.endswith(b"\n\n")
    response = scip.split_response(frame[:-2])
    assert response.status == "00" and len(response.lines) == 7
    assert scip.decode_scan(response.lines, command) == (1234, values)
    with pytest.raises(ScipError, match="values"):
        scip.decode_scan(response.lines[:-1], command)


def test_bad_responses_say_what_is_wrong() -> None:
    good = scip.response(b"VV", "00", scip.info_lines({"PROD": "URG-04LX"}))[:-2]
    kinds = []
    for bad in (good.replace(b"00P", b"00Q"), good[:-1] + b"x", b"VV", good.replace(b"00P", b"0")):
        try:
            scip.split_response(bad)
            kinds.append("ok")
        except ScipError as e:
            kinds.append(e.kind)
    assert kinds == ["checksum", "checksum", "truncated", "ok"]  # "0": SCIP 1.1's short status
    # Info lines summed without their ';' (some firmware) are good too.
    line = b"PROD:URG-04LX;"
    assert scip.split_response(b"VV\n00P\n" + line + bytes([scip.checksum(line[:-1])])).lines


def test_the_simulated_scanner_answers_as_the_firmware() -> None:
    scene = RecordedScene([[1000 + i for i in range(682)]])
    device = ScipDevice(URG_04LX, scene)
    pp = scip.split_response(device.handle(b"PP", 0.0)[:-2])
    assert scip.Geometry.from_info(scip.parse_info(pp.lines)) == URG_04LX
    assert scip.split_response(device.handle(b"GD0044072501", 0.0)[:-2]).status == "10"  # off
    assert scip.split_response(device.handle(b"BM", 0.0)[:-2]).status == "00"
    assert scip.split_response(device.handle(b"BM", 0.0)[:-2]).status == "02"  # already on
    assert device.handle(b"GD0100010904", 0.0) == b""  # answered with the next rotation
    [frame] = device.due(1e9)
    response = scip.split_response(frame[:-2])
    command = ScanCommand.parse(response.echo)
    assert scip.decode_scan(response.lines, command)[1] == [1056, 1060, 1064]  # nearest of 4
    assert scip.split_response(device.handle(b"MD0044072501003", 0.0)[:-2]).status == "00"
    scans = [scip.split_response(f[:-2]) for f in device.due(1e9)]
    assert [s.echo[-2:] for s in scans] == [b"02", b"01", b"00"] and device.next_due() is None
    assert scip.split_response(device.handle(b"MD9999999901000", 0.0)[:-2]).status == "04"


def test_the_room_scene_sees_walls_and_the_pillar() -> None:
    room = RoomScene()
    ranges = room.ranges(0.0, URG_04LX)
    front = ranges[URG_04LX.afrt - URG_04LX.amin]
    assert front == round(1500 - room.pillar)  # the pillar in front, at t = 0
    side = ranges[URG_04LX.afrt + 256 - URG_04LX.amin]  # 90 degrees left: the wall 2 m away
    assert side == 2000


def test_faults_as_asked() -> None:
    device = ScipDevice(URG_04LX, RoomScene(), faults=Faults(corrupt=3, truncate=5, repeat=7))
    device.handle(b"MD0044072501000", 0.0)
    frames = device.due(URG_04LX.period * 35 + 1e-6)
    # The 15th and 30th scans are corrupt, not truncated; the 21st and 35th not repeated.
    assert device.faults.sent == {"corrupt": 11, "truncate": 5, "repeat": 3}
    good = []
    for frame in frames:
        with contextlib.suppress(ScipError):
            good.append(scip.split_response(frame[:-2]))
    assert len(frames) == 35 + 3 and len(good) == 35 + 3 - 11 - 5


class Responses:
    """SCIP responses read from a socket one at a time (one read may hold several, or part of
    one), cut by the driver's own framer: a response ends with an empty line."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.framer = LineFramer(b"\n\n", max_length=1 << 16)  # as the driver: whole scans
        self.ready: list[bytes] = []

    def next(self) -> scip.Response:
        while not self.ready:
            chunk = self.sock.recv(65536)
            assert chunk, "the simulator closed the connection"
            self.ready += self.framer.feed(chunk)
        return scip.split_response(self.ready.pop(0))


def test_miro_sim_scip_on_a_tcp_port_replays_a_scene(tmp_path: Path) -> None:
    scans = tmp_path / "scans.txt"
    scans.write_text("# two scans of a UTM-30LX\n" + "1000 " * 1081 + "\n" + "2000 " * 1081 + "\n")
    sim = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "sim", "scip", "--tcp", "0",
         "--model", "UTM-30LX", "--scene", str(scans), "--duration", "30"],
        stdout=subprocess.PIPE,
        text=True,
        env=service_env(),
    )  # fmt: skip
    try:
        assert sim.stdout is not None
        banner = sim.stdout.readline()
        assert banner.startswith("SCIP 2.0 (UTM-30LX) on 127.0.0.1:"), banner
        port = int(banner.split(":")[1].split()[0])
        with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
            responses = Responses(sock)
            sock.sendall(b"VV\n")
            assert scip.parse_info(responses.next().lines)["PROD"] == "UTM-30LX"
            sock.sendall(b"MD0000108001000\n")
            assert responses.next().status == "00"
            seen = set()
            for _ in range(4):
                response = responses.next()
                command = ScanCommand.parse(response.echo)
                seen.add(tuple(scip.decode_scan(response.lines, command)[1]))
            assert seen == {(1000,) * 1081, (2000,) * 1081}
    finally:
        sim.send_signal(signal.SIGINT)
        out, _ = sim.communicate(timeout=10)
    assert "sent" in out and "scans" in out


def test_a_bad_scene_is_a_one_line_error(tmp_path: Path) -> None:
    scans = tmp_path / "scans.txt"
    scans.write_text("1000 2000\n1000 x\n")
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "sim", "scip", "--scene", str(scans)],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=30,
    )
    assert done.returncode == 1 and f"{scans}:2: not a line of integers" in done.stderr
    assert "Traceback" not in done.stderr
