"""`ipc://` twins of `tcp://` endpoints, for peers on the same host.

A process that binds a TCP endpoint an event channel advertises may also bind its twin: a Unix
domain socket whose path is derived from the TCP address and port and from the network namespace
(`/proc/self/ns/net`), in a folder only its user can enter. A peer that is to connect to that TCP
endpoint, finds the address is one of its own and the twin there, connects to the twin instead:
large frames cross it faster than TCP over loopback (bench/bench_events.py), and nothing changes
for peers on other hosts, in other network namespaces or of other users, which keep to TCP.

A killed process leaves its socket files behind: the first time a process uses the folder, it
removes those nobody listens on (looking at no more than SWEEP_LIMIT of them), so that the
folder does not grow with every process ever killed.

A naming service has a twin of another kind (`naming_socket`): a Linux abstract socket, named
after its port, that every user of the machine can reach and nobody leaves behind as a file.
Processes on its machine call it there for what needs an owner, because over a Unix socket the
kernel tells it which user calls (`transport.rpc.caller`).
"""

from __future__ import annotations

import contextlib
import functools
import ipaddress
import os
import socket
import stat
import sys
import time
from typing import Any

import zmq

_MAX_PATH = 100  # bytes of a Unix socket path that every platform takes
SWEEP_LIMIT = 256  # entries of the folder a process looks at when it starts using it
_SETTLED = 10.0  # seconds: a younger socket may be one just bound, not yet listening


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
    sweep(folder)
    return folder


def sweep(folder: str, limit: int = SWEEP_LIMIT) -> int:
    """Remove the socket files in `folder` that nobody listens on (left by killed processes),
    looking at `limit` entries at most; how many were removed."""
    removed = 0
    settled = time.time() - _SETTLED
    try:
        entries = os.scandir(folder)
    except OSError:
        return 0
    with entries:
        for n, entry in enumerate(entries):
            if n >= limit:
                break
            try:
                info = entry.stat(follow_symlinks=False)
            except OSError:
                continue
            if not stat.S_ISSOCK(info.st_mode) or info.st_mtime > settled:
                continue
            if _refused(entry.path):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed += 1
    return removed


@functools.cache
def network_namespace() -> str:
    """This process's network namespace (the inode of `/proc/self/ns/net`; "0" off Linux)."""
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
    path = os.path.join(folder, f"{network_namespace()}-{address.replace(':', '_')}-{port}")
    return f"ipc://{path}" if len(path.encode()) <= _MAX_PATH else None


@functools.cache
def is_local_address(address: str) -> bool:
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
    if twin is None or parts is None or not is_local_address(parts[0]):
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


def _refused(path: str) -> bool:
    """Whether the Unix socket `path` refuses connections: nobody listens there (another error,
    a full backlog, no permission, says nothing)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.setblocking(False)  # a listener with a full backlog: no waiting for it
        try:
            probe.connect(path)
        except ConnectionRefusedError:
            return True
        except OSError:
            return False
    return False


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


def naming_socket(endpoint: str) -> str | None:
    """The abstract Unix socket (`ipc://@miro-naming-PORT`, in this network namespace) beside a
    naming service at `endpoint` (tcp://HOST:PORT); None off Linux or for another transport."""
    parts = _split(endpoint)
    if parts is None or not sys.platform.startswith("linux") or not parts[1].isdigit():
        return None
    return f"ipc://@miro-naming-{parts[1]}"


def local_naming_socket(endpoint: str) -> str | None:
    """`naming_socket(endpoint)` when the naming service runs on this machine (its address is
    one of ours), else None: where this process makes its owner's calls."""
    parts = _split(endpoint)
    if parts is None or not (parts[0] in ("0.0.0.0", "*") or is_local_address(parts[0])):
        return None
    return naming_socket(endpoint)
