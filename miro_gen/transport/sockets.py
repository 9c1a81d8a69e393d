"""Every ZeroMQ socket of the transport is made here, so that each one has the same limits and
the same security (docs/SECURITY.md):

* a maximum message size (`MAXMSGSIZE`, like omniORB's `giopMaxMsgSize`): a peer that sends a
  larger frame is disconnected before the frame is read into memory;
* queues bounded in bytes: ZeroMQ counts its high-water marks in messages, so a mark is the
  per-peer byte budget divided by the largest message allowed (`queue_limit`);
* ZMTP heartbeats on every connection, so a peer that vanished is noticed within seconds;
* CURVE (authenticated encryption) when a key is configured: listening sockets are CURVE
  servers, connecting ones CURVE clients, and the admission thread (`admission.py`, the ZAP
  handler) lets in only clients that hold the key, and no more connections per listening
  socket than the cap.

The policy is per ZeroMQ context (normally one per process): `configure(context, policy)`
sets it, `listening_socket` / `connecting_socket` make sockets that follow it, `release`
stops the context's admission thread. `policy_for` decides the policy from the common options:
plain on loopback, CURVE whenever something binds, or talks to, another host, unless
`--insecure`.
"""

from __future__ import annotations

import ipaddress
import os
import socket
import threading
import weakref
from dataclasses import dataclass
from typing import Any

import zmq

from miro_gen.transport.options import UsageError

DEFAULT_MAX_MESSAGE_SIZE = 8 << 20  # bytes: a 1080p RGB image fits; omniORB's default is 2 MB
QUEUE_BYTES_PER_PEER = 128 << 20  # what a socket may hold for one peer, at most
DEFAULT_MAX_CONNECTIONS = 1024  # per listening socket; more are refused at the handshake
HEARTBEAT_IVL_MS = 500
HEARTBEAT_TIMEOUT_MS = 2000
HANDSHAKE_MS = 5000  # a connection that has not completed its handshake by then is dropped
KEY_SUFFIX = ".key_secret"
_ZAP_ENFORCE_DOMAIN = 93  # libzmq 4.3's ZMQ_ZAP_ENFORCE_DOMAIN (a draft name in pyzmq)
DEFAULT_KEY = os.path.join("~", ".config", "miro", "fleet" + KEY_SUFFIX)


@dataclass(frozen=True)
class Keys:
    """A CURVE key pair read from a ZeroMQ certificate file (`miro keys new`)."""

    path: str
    public: bytes  # Z85, 40 bytes
    secret: bytes


@dataclass(frozen=True)
class SocketPolicy:
    """What every socket of a context gets."""

    max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE
    keys: Keys | None = None  # CURVE when set
    max_connections: int = DEFAULT_MAX_CONNECTIONS

    @property
    def secure(self) -> bool:
        return self.keys is not None


PLAIN = SocketPolicy()
_policies: weakref.WeakKeyDictionary[zmq.Context[Any], SocketPolicy] = weakref.WeakKeyDictionary()
_lock = threading.Lock()


def configure(context: zmq.Context[Any], policy: SocketPolicy) -> None:
    """Make `policy` the one of the sockets made on `context` from now on."""
    with _lock:
        _policies[context] = policy


def policy(context: zmq.Context[Any]) -> SocketPolicy:
    """The policy of `context` (plain, default limits, unless configured)."""
    return _policies.get(context, PLAIN)


def queue_limit(context: zmq.Context[Any], budget: int = QUEUE_BYTES_PER_PEER) -> int:
    """A high-water mark, in messages, that holds at most `budget` bytes of the largest
    messages allowed (at least 16, at most 10,000)."""
    return max(16, min(10_000, budget // policy(context).max_message_size))


def _common(s: zmq.Socket[Any], p: SocketPolicy) -> None:
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.MAXMSGSIZE, p.max_message_size)
    s.setsockopt(zmq.HEARTBEAT_IVL, HEARTBEAT_IVL_MS)
    s.setsockopt(zmq.HEARTBEAT_TIMEOUT, HEARTBEAT_TIMEOUT_MS)
    s.setsockopt(zmq.HEARTBEAT_TTL, HEARTBEAT_TIMEOUT_MS)
    s.setsockopt(zmq.HANDSHAKE_IVL, HANDSHAKE_MS)


def listening_socket(context: zmq.Context[Any], kind: int) -> zmq.Socket[Any]:
    """A socket that will `bind`: a CURVE server when the policy has a key; every connection
    to it passes the context's admission thread (the key, the connection cap)."""
    from miro_gen.transport.admission import admission

    p = policy(context)
    s: zmq.Socket[Any] = context.socket(kind)
    _common(s, p)
    if p.keys is not None:
        s.setsockopt(zmq.CURVE_SERVER, 1)
        s.setsockopt(zmq.CURVE_SECRETKEY, p.keys.secret)
        s.setsockopt(_ZAP_ENFORCE_DOMAIN, 1)  # no admission thread: no connection
    admission(context, p).watch(s)
    return s


def connecting_socket(context: zmq.Context[Any], kind: int) -> zmq.Socket[Any]:
    """A socket that will `connect`: a CURVE client, holding the key, when the policy has
    one (the servers of a robot or fleet all have its key)."""
    p = policy(context)
    s: zmq.Socket[Any] = context.socket(kind)
    _common(s, p)
    if p.keys is not None:
        s.setsockopt(zmq.CURVE_SERVERKEY, p.keys.public)
        s.setsockopt(zmq.CURVE_PUBLICKEY, p.keys.public)
        s.setsockopt(zmq.CURVE_SECRETKEY, p.keys.secret)
    return s


def release(context: zmq.Context[Any]) -> None:
    """Stop the admission thread of `context` (after its listening sockets are closed)."""
    from miro_gen.transport.admission import stop_admission

    stop_admission(context)


# ---- keys and the choice of policy --------------------------------------------------------------


def read_keys(path: str) -> Keys:
    """The key pair in `path` (a `NAME.key_secret` file; `NAME` alone is accepted)."""
    from zmq.auth.certs import load_certificate

    full = os.path.expanduser(path)
    if not full.endswith(KEY_SUFFIX) and not os.path.exists(full):
        full += KEY_SUFFIX
    try:
        public, secret = load_certificate(full)
    except (OSError, ValueError) as e:
        raise UsageError(f"--keys {path}: cannot read a key pair: {e}") from None
    if secret is None or len(public) != 40 or len(secret) != 40:
        raise UsageError(
            f"--keys {path}: not a secret key file (make one with `miro keys new`; the "
            f"{KEY_SUFFIX} file holds the secret)"
        )
    return Keys(full, public, secret)


def is_loopback(host: str) -> bool:
    """Whether binding on `host` (an address, `*`, `localhost` or an interface name) serves
    this machine only."""
    host = host.strip("[]")
    if host in ("localhost", "lo"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # `*`, a host or interface name


def _reaches_only_here(host: str) -> bool:
    """Whether connecting to `host` (an address or a name) stays on this machine."""
    if is_loopback(host) or host in ("0.0.0.0", "*"):
        return True
    try:
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return False
    return all(ipaddress.ip_address(info[4][0]).is_loopback for info in infos)


def endpoint_host(endpoint: str) -> str:
    """The host part of `tcp://HOST:PORT`."""
    return endpoint.partition("://")[2].rpartition(":")[0].strip("[]")


def policy_for(
    *,
    keys: str | None,
    insecure: bool,
    max_message_size: int | None,
    binds: str | None = None,
    talks_to: str | None = None,
) -> SocketPolicy:
    """The policy of a process whose options say `keys` (a key file), `insecure` and
    `max_message_size`, that binds on `binds` (an address, or None) and talks to `talks_to`
    (the naming service's host). CURVE is on when a key is given, and whenever the process
    binds, or talks to, something beyond loopback, unless `insecure`; then a key is needed
    (the default key file is used when it exists)."""
    size = DEFAULT_MAX_MESSAGE_SIZE if max_message_size is None else max_message_size
    if insecure:
        return SocketPolicy(size)
    if keys:
        return SocketPolicy(size, read_keys(keys))
    wide = []
    if binds is not None and not is_loopback(binds):
        wide.append(f"binds {binds}")
    if talks_to is not None and not _reaches_only_here(talks_to):
        wide.append(f"talks to {talks_to}")
    if not wide:
        return SocketPolicy(size)
    if os.path.exists(os.path.expanduser(DEFAULT_KEY)):
        return SocketPolicy(size, read_keys(DEFAULT_KEY))
    raise UsageError(
        f"this process {wide[0]}, beyond this machine: give the robot's or fleet's key with "
        "--keys FILE (or MIRO_KEYS; make one with `miro keys new`), or --insecure to send "
        "everything in the clear to anyone who can connect"
    )
