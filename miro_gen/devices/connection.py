"""Connections: a device on the process reactor, read without blocking, reopened when it returns.

`TtyConnection` opens any pyserial URL: a device path (`/dev/ttyUSB0`), `socket://host:port`,
`rfc2217://host:port`, `loop://`. A device with a file descriptor is polled by the reactor
itself; the others are read by a thread of their own that hands what it reads to the reactor
thread, so the handler always runs there. `SockConnection` is a TCP device.

When the device disappears (a USB adapter pulled, a pseudo-terminal closed, a socket reset) the
connection tells its handler, then tries to open it again after 0.1 s, doubling the wait up to
5 s, until it is back; meanwhile `write_message` raises `DeviceUnavailable`.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any

import serial

from miro_gen.devices.handler import DevEventHandler
from miro_gen.log import logger
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")

READ_SIZE = 4096  # bytes read at most per call
RETRY_FIRST = 0.1  # seconds before the first attempt to reopen a device
RETRY_MAX = 5.0  # the longest wait between attempts


class DeviceUnavailable(ConnectionError):
    """The device is not connected (now): nothing was written."""


class Connection(ABC):
    """A device read on `reactor` into `handler`; `open()` starts it (from any thread)."""

    def __init__(
        self,
        reactor: Reactor,
        handler: DevEventHandler,
        *,
        retry: tuple[float, float] = (RETRY_FIRST, RETRY_MAX),
    ) -> None:
        self.reactor = reactor
        self.handler = handler
        self.retry_first, self.retry_max = retry
        self.connected = False
        self.connects = 0  # times the device was opened
        self.bytes_read = 0
        self._delay = self.retry_first
        self._closed = False
        self._retry_timer: int | None = None
        self._write_lock = threading.Lock()
        self._failing_since: float | None = None  # an outage is reported once, then at notice

    @property
    @abstractmethod
    def name(self) -> str:
        """The device, as the user named it."""

    # ---- what a device type provides ------------------------------------------------------------

    @abstractmethod
    def _open_device(self) -> None:
        """Open the device (may block briefly: called on a helper thread)."""

    @abstractmethod
    def _start_reading(self) -> None:
        """Start delivering input (on the reactor thread, after `_open_device`)."""

    @abstractmethod
    def _close_device(self) -> None:
        """Stop reading and close the device (on the reactor thread)."""

    @abstractmethod
    def _write(self, data: bytes) -> None:
        """Write all of `data` to the open device."""

    # ---- life cycle -----------------------------------------------------------------------------

    def open(self) -> None:
        """Connect now, and again whenever the device is lost, until `close()`."""
        self._attempt()

    def close(self) -> None:
        """Stop for good (from any thread)."""
        self._closed = True
        self.reactor.call_soon(self._shut)

    def write_message(self, data: bytes) -> None:
        """Send `data` to the device (from any thread). DeviceUnavailable when disconnected."""
        if not self.connected:
            raise DeviceUnavailable(f"{self.name} is not connected")
        try:
            with self._write_lock:
                self._write(data)
        except (OSError, serial.SerialException) as e:
            self.reactor.call_soon(self._lost, f"write failed: {e}")
            raise DeviceUnavailable(f"{self.name}: {e}") from e

    def _attempt(self) -> None:
        self._retry_timer = None
        if not self._closed:
            threading.Thread(
                target=self._open_in_thread, name="miro-device-open", daemon=True
            ).start()

    def _open_in_thread(self) -> None:
        try:
            self._open_device()
        except (OSError, ValueError, serial.SerialException) as e:
            self.reactor.call_soon(self._failed, e)
        else:
            self.reactor.call_soon(self._opened)

    def _opened(self) -> None:
        if self._closed:
            self._close_device()
            return
        self.connected = True
        self.connects += 1
        self._delay = self.retry_first
        self._failing_since = None
        self.handler.handle_connect()
        self._start_reading()
        _log.notice("%s connected", self.name)

    def _failed(self, error: BaseException) -> None:
        if self._closed:
            return
        if self._failing_since is None:
            self._failing_since = time.monotonic()
            _log.warning("cannot open %s: %s (retrying)", self.name, error)
        else:
            _log.debug("cannot open %s: %s", self.name, error)
        self._retry_timer = self.reactor.schedule_timer(self._delay, 0, lambda _: self._attempt())
        self._delay = min(self._delay * 2, self.retry_max)

    def _lost(self, why: str) -> None:
        """The device stopped working (on the reactor thread)."""
        if not self.connected:
            return
        self.connected = False
        self._close_device()
        self.handler.handle_disconnect()
        if self._closed:
            return
        _log.warning("%s lost: %s (reconnecting)", self.name, why)
        self._failing_since = time.monotonic()
        self._retry_timer = self.reactor.schedule_timer(self._delay, 0, lambda _: self._attempt())

    def _shut(self) -> None:
        if self._retry_timer is not None:
            self.reactor.cancel_timer(self._retry_timer)
        if self.connected:
            self.connected = False
            self._close_device()
            self.handler.handle_disconnect()

    def _deliver(self, data: bytes, stamp: float) -> None:
        self.bytes_read += len(data)
        self.handler.handle_input(data, stamp)


class TtyConnection(Connection):
    """A serial device (any pyserial URL), with `settings` the keyword arguments of
    `serial.Serial` (baudrate, bytesize, parity, stopbits, ...; a `Serial_Params` parameter's
    `pyserial()` gives them)."""

    def __init__(
        self,
        reactor: Reactor,
        handler: DevEventHandler,
        device: str,
        settings: Mapping[str, Any] | None = None,
        *,
        retry: tuple[float, float] = (RETRY_FIRST, RETRY_MAX),
    ) -> None:
        super().__init__(reactor, handler, retry=retry)
        self.device = device
        self.settings = dict(settings or {})
        self.serial: serial.SerialBase | None = None
        self._fd: int | None = None
        self._reader: threading.Thread | None = None
        self._stop_reader = threading.Event()

    @property
    def name(self) -> str:
        return self.device

    def _open_device(self) -> None:
        port = serial.serial_for_url(self.device, do_not_open=True, **self.settings)
        port.timeout = 0  # never block the reactor
        port.open()
        self.serial = port

    def _start_reading(self) -> None:
        assert self.serial is not None
        try:
            self._fd = self.serial.fileno()
        except (AttributeError, OSError, serial.SerialException):  # io.UnsupportedOperation
            self._fd = None
        if self._fd is not None:
            self.reactor.register(self._fd, self._readable)
            return
        self._stop_reader = threading.Event()
        self._reader = threading.Thread(
            target=self._read_in_thread,
            args=(self.serial, self._stop_reader),
            name="miro-device-read",
            daemon=True,
        )
        self._reader.start()

    def _readable(self) -> None:
        assert self._fd is not None
        try:
            data = os.read(self._fd, READ_SIZE)
        except BlockingIOError:
            return
        except OSError as e:  # EIO: the other end of a pseudo-terminal, or the USB device, left
            self._lost(e.strerror or str(e))
            return
        if not data:
            self._lost("end of file")
            return
        self._deliver(data, time.time())

    def _read_in_thread(self, port: Any, stop: threading.Event) -> None:
        port.timeout = 0.1  # so that `stop` is noticed
        while not stop.is_set():
            try:  # one byte (waiting for it), then whatever else has arrived
                data = port.read(max(1, min(port.in_waiting, READ_SIZE)))
            except (OSError, serial.SerialException) as e:
                if not stop.is_set():
                    self.reactor.call_soon(self._lost, str(e))
                return
            if data:
                self.reactor.call_soon(self._deliver, data, time.time())

    def _close_device(self) -> None:
        if self._fd is not None:
            self.reactor.unregister(self._fd)
            self._fd = None
        self._stop_reader.set()
        if self.serial is not None:
            try:
                self.serial.close()
            except (OSError, serial.SerialException) as e:
                _log.debug("closing %s: %s", self.device, e)
            self.serial = None

    def _write(self, data: bytes) -> None:
        port = self.serial
        if port is None:
            raise DeviceUnavailable(f"{self.device} is not connected")
        if self._fd is not None:  # the descriptor is non-blocking: write until all is out
            view = memoryview(data)
            while view:
                try:
                    view = view[os.write(self._fd, view) :]
                except BlockingIOError:
                    time.sleep(0.001)
        else:
            port.write(data)


class SockConnection(Connection):
    """A device on a TCP port (a laser scanner, a serial-to-Ethernet adapter)."""

    def __init__(
        self,
        reactor: Reactor,
        handler: DevEventHandler,
        host: str,
        port: int,
        *,
        connect_timeout: float = 2.0,
        retry: tuple[float, float] = (RETRY_FIRST, RETRY_MAX),
    ) -> None:
        super().__init__(reactor, handler, retry=retry)
        self.address = (host, port)
        self.connect_timeout = connect_timeout
        self.socket: socket.socket | None = None

    @property
    def name(self) -> str:
        return f"{self.address[0]}:{self.address[1]}"

    def _open_device(self) -> None:
        sock = socket.create_connection(self.address, timeout=self.connect_timeout)
        sock.setblocking(False)
        self.socket = sock

    def _start_reading(self) -> None:
        assert self.socket is not None
        self.reactor.register(self.socket, self._readable)

    def _readable(self) -> None:
        assert self.socket is not None
        try:
            data = self.socket.recv(READ_SIZE)
        except BlockingIOError:
            return
        except OSError as e:
            self._lost(e.strerror or str(e))
            return
        if not data:
            self._lost("the device closed the connection")
            return
        self._deliver(data, time.time())

    def _close_device(self) -> None:
        if self.socket is not None:
            self.reactor.unregister(self.socket)
            self.socket.close()
            self.socket = None

    def _write(self, data: bytes) -> None:
        sock = self.socket
        if sock is None:
            raise DeviceUnavailable(f"{self.name} is not connected")
        sock.setblocking(True)  # a short, bounded wait rather than a partial message
        try:
            sock.settimeout(self.connect_timeout)
            sock.sendall(data)
        finally:
            sock.setblocking(False)
