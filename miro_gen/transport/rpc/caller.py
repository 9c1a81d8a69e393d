"""Who is calling: what a server can check about the peer behind the request it serves.

A servant that must know who calls (the naming service: who owns a name) asks `current()`
while it runs. Its adapter reads, for each request, what ZeroMQ learnt of the connection it
came on (`Peer-Address`, `User-Id`; the adapter's `identify_callers`) and makes it a
*principal*, a string two requests share exactly when they come from the same checked party:

* `uid:N` — a process of user N on this machine, connected over a Unix socket: the kernel
  says who it is (SO_PEERCRED; libzmq writes it into the peer address as `:UID:GID:PID`).
  Nobody can pose as another user this way.
* `key:Z85@ADDRESS` — a process holding the CURVE key Z85 (the robot's or fleet's), at
  ADDRESS: the admission thread vouches for the key (`transport.sockets`), TCP for the
  address.
* `host:ADDRESS` — a process at ADDRESS without a key (insecure mode beyond loopback).
* `loopback` — a process on this machine connected over TCP: any user, any address of
  127/8 (a caller picks its source address), so nothing is known about it.

IIOP callers (the CosNaming door of `miro naming --iiop-endpoint`) come over TCP without keys
(`caller_of_tcp`): one on this machine is `uid:N` when the kernel's table of TCP sockets
(`/proc/net/tcp`, `tcp6`) names the user whose socket is the other end of the connection, as
identd does, else `loopback`; one beyond is `host:ADDRESS` (served only with --insecure).

`verified` says whether the principal tells one party from another (all but `loopback`).
"""

from __future__ import annotations

import functools
import ipaddress
import re
import socket
import struct
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from miro_gen.transport.local import is_local_address

_CREDENTIALS = re.compile(r":(\d+):(\d+):(\d+)$")  # what libzmq appends for a Unix socket peer
LOOPBACK = "loopback"


@dataclass(frozen=True)
class Caller:
    """The checked identity of a request's sender."""

    principal: str
    verified: bool
    pid: int = 0  # the process, when the kernel said (a Unix socket)

    @property
    def local(self) -> bool:
        """Whether it runs on this machine (a Unix socket, or TCP from an address of ours)."""
        return self.principal.startswith("uid:") or self.principal == LOOPBACK


def caller_of(peer_address: str, user_id: str) -> Caller:
    """The caller whose connection ZeroMQ describes with `peer_address` and `user_id` (what
    the admission thread answered: the CURVE key, or empty)."""
    m = _CREDENTIALS.search(peer_address)
    if m is not None:
        return Caller(f"uid:{m.group(1)}", True, int(m.group(3)))
    address = peer_address.strip("[]")
    if not address or _is_ours(address):
        return Caller(LOOPBACK, False)
    if user_id:
        return Caller(f"key:{user_id}@{address}", True)
    return Caller(f"host:{address}", True)


@functools.lru_cache(maxsize=256)
def _is_ours(address: str) -> bool:
    """Whether `address` is one of this machine's (loopback, or an interface's)."""
    try:
        if ipaddress.ip_address(address).is_loopback:
            return True
    except ValueError:
        return False
    return is_local_address(address)


_current = threading.local()


def current() -> Caller | None:
    """The caller of the request this thread serves, when its adapter identifies callers."""
    caller: Caller | None = getattr(_current, "caller", None)
    return caller


@contextmanager
def serving(caller: Caller | None) -> Iterator[None]:
    """While inside, `current()` is `caller` on this thread."""
    _current.caller = caller
    try:
        yield
    finally:
        _current.caller = None


def caller_of_tcp(peer: tuple[str, int], here: tuple[str, int]) -> Caller:
    """The caller at the far end of a TCP connection from `peer` to `here` (host, port): the
    user whose socket it is, for one on this machine (the kernel's table of TCP sockets)."""
    address = peer[0].partition("%")[0]
    if not _is_ours(address):
        return Caller(f"host:{address}", True)
    uid = tcp_owner(peer, here)
    if uid is None:
        return Caller(LOOPBACK, False)
    return Caller(f"uid:{uid}", True)


def _proc_address(host: str, port: int) -> str | None:
    """`host`:`port` as /proc/net/tcp{,6} spell it: the address's 32-bit words in this
    machine's byte order, in hexadecimal, and the port."""
    try:
        packed = socket.inet_pton(socket.AF_INET6 if ":" in host else socket.AF_INET, host)
    except OSError:
        return None
    words = struct.unpack(f"={len(packed) // 4}I", packed)
    return "".join(f"{w:08X}" for w in words) + f":{port:04X}"


def tcp_owner(peer: tuple[str, int], here: tuple[str, int]) -> int | None:
    """The user id owning this machine's TCP socket at `peer` connected to `here` (None: not
    found, or not Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    local, remote = _proc_address(*peer), _proc_address(*here)
    if local is None or remote is None:
        return None
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            with open(table) as f:
                next(f, None)  # the heading
                for line in f:
                    fields = line.split()
                    if len(fields) > 7 and fields[1] == local and fields[2] == remote:
                        return int(fields[7])
        except (OSError, ValueError):
            continue
    return None
