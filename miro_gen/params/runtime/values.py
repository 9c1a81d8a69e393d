"""Parameter value types that Python lacks: ACE's address, time, serial and scheduling types.

makeParams mapped them onto ACE classes; here they are small immutable or pydantic types, each with
the text form the run-time XML uses and a bridge to the Python library that uses them (pyserial,
`os.sched_setscheduler`).
"""

from __future__ import annotations

import datetime
import math
from typing import Any, NamedTuple


class InetAddr(NamedTuple):
    """`ACE_INET_Addr`: a host and a port, written `host:port` (`[::1]:80` for IPv6)."""

    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


def parse_inet_addr(text: str) -> InetAddr:
    text = text.strip()
    if text.startswith("["):
        host, sep, port = text[1:].partition("]:")
    else:
        host, sep, port = text.rpartition(":")
    if not sep or not host or (":" in host and not text.startswith("[")):
        raise ValueError(f"expected host:port, got {text!r}")
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"the port of {text!r} is not a number") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"the port of {text!r} is outside 0..65535")
    return InetAddr(host, number)


def time_value(sec: int = 0, usec: int = 0) -> datetime.timedelta:
    """`ACE_Time_Value(sec, usec)` as a `timedelta`."""
    return datetime.timedelta(seconds=sec, microseconds=usec)


def parse_time_value(text: str) -> datetime.timedelta:
    """ "sec, usec" (ACE's two fields), "sec usec", or a number of seconds ("0.25")."""
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        if len(parts) == 2:
            return time_value(int(parts[0]), int(parts[1]))
        if len(parts) == 1:
            seconds = float(parts[0])
            if not math.isfinite(seconds):
                raise ValueError
            return datetime.timedelta(seconds=seconds)
    except (ValueError, OverflowError):
        pass
    raise ValueError(f'expected "sec, usec" or seconds, got {text!r}')


def format_time_value(value: datetime.timedelta) -> str:
    total_usec = (value.days * 86400 + value.seconds) * 1_000_000 + value.microseconds
    sec, usec = divmod(total_usec, 1_000_000)
    if sec < 0 and usec:  # ACE normalises to the same sign in both fields
        sec, usec = sec + 1, usec - 1_000_000
    return f"{sec}, {usec}"


def deg2rad(degrees: float) -> float:
    """`Miro::deg2Rad`."""
    return math.radians(degrees)


def rad2deg(radians: float) -> float:
    """`Miro::rad2Deg`."""
    return math.degrees(radians)


def pyserial_parity(parity_enabled: bool, mode: str) -> str:
    """ACE's parity settings as a pyserial parity constant ("N", "E", "O", "M", "S")."""
    if not parity_enabled:
        return "N"
    return {"even": "E", "odd": "O", "mark": "M", "space": "S"}.get(mode.lower(), "N")


def serial_settings(params: Any) -> dict[str, Any]:
    """The keyword arguments of `serial.Serial` for `ACE_TTY_IO::Serial_Params` values."""
    stop = {1: 1, 2: 2}.get(params.stopbits, 1)
    timeout = None if params.readtimeoutmsec < 0 else params.readtimeoutmsec / 1000.0
    return {
        "baudrate": params.baudrate,
        "bytesize": params.databits,
        "parity": pyserial_parity(params.parityenb, params.paritymode),
        "stopbits": stop,
        "xonxoff": params.xinenb or params.xoutenb,
        "rtscts": params.ctsenb or params.rtsenb not in (0, False),
        "timeout": timeout,
    }
