"""Device connections on a running reactor: a real pseudo-terminal, a TCP device, pyserial's
loop://; split reads, writes, and a device that vanishes and comes back."""

from __future__ import annotations

import socket
import threading
from pathlib import Path

import pytest
from loopback import eventually

from miro_gen.devices import (
    Connection,
    DevConsumer,
    DevEventHandler,
    DevMessage,
    LineFramer,
    SockConnection,
    TtyConnection,
)
from miro_gen.devices.connection import DeviceUnavailable
from miro_gen.sim.pty_device import PtyDevice
from miro_gen.transport.reactor import Reactor

FAST_RETRY = (0.05, 0.2)


class Messages(DevConsumer):
    def __init__(self) -> None:
        self.messages: list[DevMessage] = []
        self.changes: list[bool] = []

    def handle_message(self, message: DevMessage) -> None:
        if message.data == b"boom":
            raise ValueError("a consumer bug")
        self.messages.append(message)

    def connection_changed(self, connected: bool) -> None:
        self.changes.append(connected)

    def data(self) -> list[bytes]:
        return [m.data for m in self.messages]


def line_device(
    reactor: Reactor, make: type[Connection], *args: object
) -> tuple[Connection, Messages]:
    consumer = Messages()
    conn = make(reactor, DevEventHandler(LineFramer(), consumer), *args, retry=FAST_RETRY)  # type: ignore[call-arg]
    conn.open()
    return conn, consumer


def test_lines_split_across_writes_arrive_whole(reactor: Reactor, tmp_path: Path) -> None:
    pty = PtyDevice(tmp_path / "gps0")
    conn, got = line_device(reactor, TtyConnection, pty.path, {"baudrate": 4800})
    try:
        eventually(lambda: conn.connected)
        for piece in (b"$GPGGA,1", b"23*00\r", b"\n$GPRMC", b",4*00\r\n", b"boom\r\nlast\r\n"):
            pty.write(piece)
        eventually(lambda: got.data() == [b"$GPGGA,123*00", b"$GPRMC,4*00", b"last"])
        assert conn.handler.failed == 1  # the consumer's exception did not stop the reading
        stamps = [m.stamp for m in got.messages]
        assert stamps == sorted(stamps)
        conn.write_message(b"$PCMD,1*00\r\n")
        assert pty.read(12) == b"$PCMD,1*00\r\n"
    finally:
        conn.close()
        pty.vanish()


def test_a_device_that_vanishes_and_comes_back(reactor: Reactor, tmp_path: Path) -> None:
    pty = PtyDevice(tmp_path / "gps0")
    conn, got = line_device(reactor, TtyConnection, pty.path)
    try:
        eventually(lambda: conn.connected)
        pty.write(b"before\r\npartial-")
        eventually(lambda: got.data() == [b"before"])
        pty.vanish()
        eventually(lambda: not conn.connected)
        with pytest.raises(DeviceUnavailable):
            conn.write_message(b"x")
        threading.Event().wait(0.3)  # a few failed attempts to reopen it
        pty.appear()
        eventually(lambda: conn.connected)
        pty.write(b"after\r\n")
        eventually(lambda: got.data() == [b"before", b"after"])  # no "partial-after"
        assert got.changes == [True, False, True]
        assert conn.connects == 2
    finally:
        conn.close()
        pty.vanish()


def test_a_device_missing_at_start_is_waited_for(reactor: Reactor, tmp_path: Path) -> None:
    link = tmp_path / "gps0"
    conn, got = line_device(reactor, TtyConnection, str(link))
    threading.Event().wait(0.3)
    assert not conn.connected
    pty = PtyDevice(link)
    try:
        eventually(lambda: conn.connected)
        pty.write(b"hello\n")
        eventually(lambda: got.data() == [b"hello"])
    finally:
        conn.close()
        pty.vanish()


def test_a_url_without_a_descriptor_is_read_by_a_thread(reactor: Reactor) -> None:
    conn, got = line_device(reactor, TtyConnection, "loop://")
    try:
        eventually(lambda: conn.connected)
        conn.write_message(b"echo 1\n")
        conn.write_message(b"echo 2\n")
        eventually(lambda: got.data() == [b"echo 1", b"echo 2"])
    finally:
        conn.close()


def test_a_tcp_device_and_its_restart(reactor: Reactor) -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    conn, got = line_device(reactor, SockConnection, "127.0.0.1", port)
    try:
        peer, _ = server.accept()
        peer.sendall(b"scan 1\nsca")
        peer.sendall(b"n 2\n")
        eventually(lambda: got.data() == [b"scan 1", b"scan 2"])
        conn.write_message(b"start\n")
        assert peer.recv(6) == b"start\n"
        peer.close()  # the device restarts
        eventually(lambda: not conn.connected)
        peer, _ = server.accept()
        eventually(lambda: conn.connected)
        peer.sendall(b"scan 3\n")
        eventually(lambda: got.data()[-1:] == [b"scan 3"])
        peer.close()
    finally:
        conn.close()
        server.close()
