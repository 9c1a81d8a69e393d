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

`verified` says whether the principal tells one party from another (all but `loopback`).
"""

from __future__ import annotations

import functools
import ipaddress
import re
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
