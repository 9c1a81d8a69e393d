"""`ipc://` twins of `tcp://` endpoints, for peers on the same host.

A process that binds a TCP endpoint an event channel advertises may also bind its twin: a Unix
domain socket whose path is derived from the TCP address and port and from the network namespace
(`/proc/self/ns/net`), in a folder only its user can enter. A peer that is to connect to that TCP
endpoint, finds the address is one of its own and the twin there, connects to the twin instead:
large frames cross it faster than TCP over loopback (bench/bench_events.py), and nothing changes
for peers on other hosts, in other network namespaces or of other users, which keep to TCP.
"""

from __future__ import annotations

import contextlib
import functools
import ipaddress
import os
import socket
import sys
from typing import Any

import zmq

_MAX_PATH = 100  # bytes of a Unix socket path that every platform takes


@functools.cache
def _folder() -> str | None:
    """This user's folder for the sockets (made once, mode 0700), or None where there is none."""
    if not sys.platform.startswith("linux"):
        return None
    import tempfile  # here: servers without event channels never need it (1 MB at start)

    base = os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()
    folder = os.path.join(base, f"miro-{os.getuid()}")
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
        info = os.stat(folder)
    except OSError:
        return None
    if info.st_uid != os.getuid() or info.st_mode & 0o077:
        return None  # someone else's, or open to others: not for our sockets
    return folder


@functools.cache
def _namespace() -> str:
    try:
        return str(os.stat("/proc/self/ns/net").st_ino)
    except OSError:
        return "0"


def _split(endpoint: str) -> tuple[str, str] | None:
    """(address, port) of a tcp:// endpoint; None for any other kind."""
    proto, _, rest = endpoint.partition("://")
    if proto != "tcp":
        return None
    address, _, port = rest.rpartition(":")
    return address.strip("[]"), port


def ipc_twin(endpoint: str) -> str | None:
    """The ipc:// twin of a tcp:// endpoint, or None (not TCP, or no folder for it here)."""
    parts = _split(endpoint)
    folder = _folder()
    if parts is None or folder is None:
        return None
    address, port = parts
    path = os.path.join(folder, f"{_namespace()}-{address.replace(':', '_')}-{port}")
    return f"ipc://{path}" if len(path.encode()) <= _MAX_PATH else None


@functools.cache
def _is_local(address: str) -> bool:
    """Whether `address` is one of this host's (in this network namespace)."""
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return address == "localhost"
    if ip.is_loopback:
        return True
    family = socket.AF_INET6 if ip.version == 6 else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as s:
        try:
            s.bind((address, 0))  # only an address of one's own interfaces can be bound
        except OSError:
            return False
    return True


def nearest(endpoint: str) -> str:
    """The endpoint to connect to for `endpoint`: its ipc:// twin when it is bound on this host,
    else `endpoint` itself."""
    twin = ipc_twin(endpoint)
    parts = _split(endpoint)
    if twin is None or parts is None or not _is_local(parts[0]):
        return endpoint
    return twin if _listening(twin[len("ipc://") :]) else endpoint


def _listening(path: str) -> bool:
    """Whether a process listens on the Unix socket `path`: a file left by one that was killed
    (or a twin of a port that has changed hands) refuses the connection at once."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        try:
            probe.connect(path)
        except OSError:
            return False
    return True


def bind_twin(sock: zmq.Socket[Any], endpoint: str) -> str | None:
    """Bind `sock` (a zmq socket) also to the ipc:// twin of `endpoint`; the twin, or None."""
    twin = ipc_twin(endpoint)
    if twin is None:
        return None
    with contextlib.suppress(FileNotFoundError):
        os.unlink(twin[len("ipc://") :])  # a socket left by a process that died on this port
    try:
        sock.bind(twin)
    except zmq.ZMQError:  # the twin is an optimisation: TCP serves anyway
        return None
    return twin
