"""Every ZeroMQ socket of the transport is made here, so that each one has the same limits and
the same security (docs/SECURITY.md):

* a maximum message size (`MAXMSGSIZE`, like omniORB's `giopMaxMsgSize`): a peer that sends a
  larger frame is disconnected before the frame is read into memory;
* queues bounded in bytes: ZeroMQ counts its high-water marks in messages, so a mark is the
  per-peer byte budget divided by the largest message allowed (`queue_limit`);
* ZMTP heartbeats on every connection, so a peer that vanished is noticed within seconds;
* CURVE (authenticated encryption) when a key is configured: listening sockets are CURVE
  servers, connecting ones CURVE clients, and the admission thread (below: the ZAP handler)
  lets in only clients that hold the key, and no more connections per listening socket than
  the cap.

The policy is per ZeroMQ context (normally one per process): `configure(context, policy)`
sets it, `listening_socket` / `connecting_socket` make sockets that follow it. `policy_for`
decides the policy from the common options:
plain on loopback, CURVE whenever something binds, or talks to, another host, unless
`--insecure`.
"""

from __future__ import annotations

import ipaddress
import itertools
import os
import queue
import socket
import struct
import threading
import weakref
from dataclasses import dataclass
from typing import Any

import zmq
from zmq.utils import z85

from miro_gen.exceptions import actionable
from miro_gen.log import PeerWarnings, logger
from miro_gen.transport.keyfiles import DEFAULT_KEY as DEFAULT_KEY  # (its users look here)
from miro_gen.transport.keyfiles import read_key_pair
from miro_gen.transport.usage import UsageError

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts
# What ZeroMQ refuses (an address in use, one it cannot bind) is the user's to fix: one line.
actionable(zmq.ZMQError, lambda e: f"ZeroMQ: {e}")

DEFAULT_MAX_MESSAGE_SIZE = 8 << 20  # bytes: a 1080p RGB image fits; omniORB's default is 2 MB
QUEUE_BYTES_PER_PEER = 128 << 20  # what a socket may hold for one peer, at most
# ... but never fewer frames than this: libzmq tells a writer how far its reader got only every
# half high-water mark, so a mark of 16 dropped bursts of ten small frames sent to a consumer
# that kept up. The price: a slow reader of maximum-size frames may hold 64 of them.
MIN_QUEUE_FRAMES = 64
DEFAULT_MAX_CONNECTIONS = 1024  # per listening socket; more are refused at the handshake
HEARTBEAT_IVL_MS = 500
HEARTBEAT_TIMEOUT_MS = 2000
HANDSHAKE_MS = 5000  # a connection that has not completed its handshake by then is dropped
_ZAP_ENFORCE_DOMAIN = 93  # libzmq 4.3's ZMQ_ZAP_ENFORCE_DOMAIN (a draft name in pyzmq)


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
SERVES = "call its objects, and subscribe to or publish its events"  # a stranger, --insecure
_said: set[str] = set()  # the --insecure warnings given
_monitors = itertools.count(1)
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
    messages allowed, but never fewer than MIN_QUEUE_FRAMES (at most 10,000)."""
    return max(MIN_QUEUE_FRAMES, min(10_000, budget // policy(context).max_message_size))


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
    p = policy(context)
    s: zmq.Socket[Any] = context.socket(kind)
    _common(s, p)
    if p.keys is not None:
        s.setsockopt(zmq.CURVE_SERVER, 1)
        s.setsockopt(zmq.CURVE_SECRETKEY, p.keys.secret)
        s.setsockopt(_ZAP_ENFORCE_DOMAIN, 1)  # no admission thread: no connection
    admission(context, p).watch(s)
    return s


def monitor(s: zmq.Socket[Any], events: int) -> zmq.Socket[Any]:
    """A PAIR socket receiving `events` of `s`, at an address of its own: pyzmq's default
    address comes from the socket's file descriptor, which a socket closed a moment ago (its
    monitor not yet gone: ZeroMQ closes in the background) may still hold."""
    return s.get_monitor_socket(events, f"inproc://miro-monitor-{next(_monitors)}")


_MONITOR_EVENT = struct.Struct("=Hi")


def monitor_event(frames: list[bytes]) -> tuple[int, int]:
    """The event and its value (a file descriptor, an error number) of a message a monitor
    socket received: libzmq's layout, read here because pyzmq's `zmq.utils.monitor` imports
    asyncio (8 MB and tens of milliseconds at every service's start)."""
    if len(frames) != 2 or len(frames[0]) != _MONITOR_EVENT.size:
        raise RuntimeError(f"not a monitor event: {frames!r}")
    event, value = _MONITOR_EVENT.unpack(frames[0])
    return event, value


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


# ---- keys and the choice of policy --------------------------------------------------------------


def read_keys(path: str) -> Keys:
    """The key pair in `path` (a `NAME.key_secret` file; `NAME` alone is accepted), refused
    when others may read it (transport.keyfiles)."""
    return Keys(*read_key_pair(path))


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


def _stays_here(host: str, binding: bool) -> bool:
    """Whether binding on (`binding`), or connecting to, `host` (an address, a name, `*`)
    stays on this machine: binding `0.0.0.0` serves every interface, connecting to it reaches
    this machine."""
    if is_loopback(host):
        return True
    if host in ("0.0.0.0", "*"):
        return not binding
    try:
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return False
    return all(ipaddress.ip_address(info[4][0]).is_loopback for info in infos)


def stays_here(host: str, binding: bool) -> bool:
    """Whether binding on (`binding`), or connecting to, `host` stays on this machine: the
    line CURVE is drawn at, which IIOP follows too (`service/iiop.py`)."""
    return _stays_here(host, binding)


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
    serves: str = SERVES,
) -> SocketPolicy:
    """The policy of a process whose options say `keys` (a key file), `insecure` and
    `max_message_size`, that binds on `binds` (an address, or None) and talks to `talks_to`
    (the naming service's host). CURVE is on when a key is given, and whenever the process
    binds, or talks to, something beyond loopback, unless `insecure`; then a key is needed
    (the default key file is used when it exists). With `insecure`, the process says (as a
    warning, once) what that opens: `serves` is what a stranger may then do with what it
    binds."""
    size = DEFAULT_MAX_MESSAGE_SIZE if max_message_size is None else max_message_size
    wide_bind = binds if binds is not None and not _stays_here(binds, binding=True) else None
    wide_peer = None
    if talks_to is not None and not _stays_here(talks_to, binding=False):
        wide_peer = talks_to
    if insecure:
        for line in insecure_exposure(keys, wide_bind, wide_peer, serves):
            say_once(line)
        return SocketPolicy(size)
    if keys:
        return SocketPolicy(size, read_keys(keys))
    wide = []
    if wide_bind is not None:
        wide.append(f"binds {wide_bind}")
    if wide_peer is not None:
        wide.append(f"talks to {wide_peer}")
    if not wide:
        return SocketPolicy(size)
    if os.path.exists(os.path.expanduser(DEFAULT_KEY)):
        return SocketPolicy(size, read_keys(DEFAULT_KEY))
    raise UsageError(
        f"this process {wide[0]}, beyond this machine: give the robot's or fleet's key with "
        "--keys FILE (or MIRO_KEYS; make one with `miro keys new`), or --insecure to send "
        "everything in the clear to anyone who can connect"
    )


def insecure_exposure(
    keys: str | None, binds: str | None, talks_to: str | None, serves: str = SERVES
) -> list[str]:
    """What `--insecure` opens, one line each, for a process that binds on `binds` and talks to
    `talks_to` beyond loopback (None: on loopback), and was given the key `keys`."""
    lines = []
    default_key = os.path.expanduser(DEFAULT_KEY)
    if keys or ((binds or talks_to) and os.path.exists(default_key)):
        lines.append(f"--insecure: the key {keys or default_key} is not used")
    if binds is not None:
        where = "every interface (0.0.0.0)" if binds in ("0.0.0.0", "*") else binds
        lines.append(
            f"--insecure: serving on {where} with neither key nor encryption: anyone who can "
            f"reach this machine may {serves}, and anyone on the network between may read "
            "and change what is said"
        )
    if talks_to is not None:
        lines.append(
            f"--insecure: talking to the naming service at {talks_to}, and to what it names, "
            "with neither key nor encryption: anyone on the network between may read and "
            "change what is said, or answer in their place"
        )
    return lines


def say_once(line: str) -> None:
    """A warning, once per process (a process makes its policy more than once)."""
    if line not in _said:
        _said.add(line)
        _log.warning("%s", line)


# ---- admission: the ZAP handler of a context (ZeroMQ RFC 27), in a thread of its own ---------
#
# libzmq asks it about every connection to a listening socket (which names its ZAP domain)
# before the first message passes. It answers no when CURVE is on and the client's long-term
# public key is not the robot's or fleet's key (only a process holding the secret key can
# complete the handshake with that public key), or when the socket already has
# `max_connections` connections: libzmq has no connection cap of its own, so the thread counts
# them from the socket's monitor (accepted minus disconnected). Answers take microseconds; the
# thread never runs services' code. It lives as long as its context and ends when the context
# is terminated: stopping it earlier and starting another would race with ZeroMQ, which
# releases the handler's address in the background, so that a connection could be handed to
# the old, deaf one. Counters (`admitted`, `refused_key`, `refused_cap`) are for tests and
# benchmarks.

ZAP_ENDPOINT = "inproc://zeromq.zap.01"
_EVENTS = zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED | zmq.EVENT_MONITOR_STOPPED
_domains = itertools.count(1)


class Admission(threading.Thread):
    """The ZAP handler of one context."""

    def __init__(self, context: zmq.Context[Any], p: SocketPolicy) -> None:
        super().__init__(name="miro-admission", daemon=True)
        self.context = context
        self.policy = p
        self.admitted = 0
        self.refused_key = 0
        self.refused_cap = 0
        self._new: queue.SimpleQueue[tuple[bytes, zmq.Socket[Any]]] = queue.SimpleQueue()
        self._live: dict[bytes, set[int]] = {}  # domain -> descriptors of its connections
        self._monitors: dict[zmq.Socket[Any], bytes] = {}
        self._ready = threading.Event()
        self._zap: zmq.Socket[Any] | None = None
        self.start()
        self._ready.wait(5)

    def watch(self, s: zmq.Socket[Any]) -> None:
        """Admit connections to `s` (a listening socket, before it binds). Call from the
        socket's thread: its monitor is made there and handed over to this one."""
        domain = f"miro-{next(_domains)}".encode()
        s.setsockopt(zmq.ZAP_DOMAIN, domain)
        self._new.put((domain, monitor(s, _EVENTS)))

    # ---- the thread ---------------------------------------------------------------------------

    def run(self) -> None:
        zap = self._zap = self.context.socket(zmq.REP)
        zap.setsockopt(zmq.LINGER, 0)
        try:
            zap.bind(ZAP_ENDPOINT)
        except zmq.ZMQError as e:  # another ZAP handler owns this context
            _log.error("cannot admit connections: %s", e)
            zap.close(0)
            self._ready.set()
            return
        self._ready.set()
        poller = zmq.Poller()
        poller.register(zap, zmq.POLLIN)
        try:
            while True:  # until the context is terminated
                self._take_new(poller)
                for ready, _ in poller.poll(1000):
                    if ready is zap:
                        self._answer(zap, poller)
                    else:
                        self._read_monitor(ready, poller)
        except zmq.ZMQError:  # the context is terminating
            pass
        finally:
            while not self._new.empty():
                self._new.get_nowait()[1].close(0)
            for monitor in list(self._monitors):
                monitor.close(0)
            zap.close(0)

    def _take_new(self, poller: zmq.Poller) -> None:
        while True:
            try:
                domain, monitor = self._new.get_nowait()
            except queue.Empty:
                return
            self._monitors[monitor] = domain
            self._live.setdefault(domain, set())
            poller.register(monitor, zmq.POLLIN)

    def _read_monitor(self, monitor: zmq.Socket[Any], poller: zmq.Poller) -> None:
        domain = self._monitors[monitor]
        live = self._live[domain]
        while True:
            try:
                kind, fd = monitor_event(monitor.recv_multipart(zmq.NOBLOCK))
            except zmq.Again:
                return
            if kind == zmq.EVENT_ACCEPTED:
                live.add(fd)
            elif kind == zmq.EVENT_DISCONNECTED:
                live.discard(fd)
            elif kind == zmq.EVENT_MONITOR_STOPPED:  # the socket was closed
                poller.unregister(monitor)
                del self._monitors[monitor]
                del self._live[domain]
                monitor.close(0)
                return

    def _answer(self, zap: zmq.Socket[Any], poller: zmq.Poller) -> None:
        request = zap.recv_multipart()
        if len(request) < 6:  # not libzmq: nothing sensible to answer
            zap.send_multipart([b"1.0", request[1] if len(request) > 1 else b"", b"400", b""])
            return
        _, request_id, domain, address, _, mechanism, *credentials = request
        # The connection being asked about was accepted before its handshake began: make sure
        # its ACCEPTED event has been counted.
        self._take_new(poller)
        for monitor, d in list(self._monitors.items()):
            if d == domain:
                self._read_monitor(monitor, poller)
        status, text, user = b"200", b"OK", b""
        if len(self._live.get(domain, ())) > self.policy.max_connections:
            status, text = b"400", b"too many connections"
            self.refused_cap += 1
        elif self.policy.keys is not None and (
            mechanism != b"CURVE"
            or not credentials
            or z85.encode(credentials[0]) != self.policy.keys.public
        ):
            status, text = b"400", b"unknown key"
            self.refused_key += 1
        else:
            self.admitted += 1
            if mechanism == b"CURVE" and credentials:  # who it is, for transport.rpc.caller
                user = z85.encode(credentials[0])
        zap.send_multipart([b"1.0", request_id, status, text, user, b""])
        if status != b"200":
            _peer_warnings.warning(
                "refused a connection from %s: %s", address.decode(errors="replace"), text.decode()
            )


_admissions: dict[int, Admission] = {}
_admissions_lock = threading.Lock()


def admission(context: zmq.Context[Any], p: SocketPolicy) -> Admission:
    """The admission thread of `context`, started on first use (with the policy `p`; a later
    policy of the context replaces it for the connections that follow)."""
    with _admissions_lock:
        current = _admissions.get(id(context))
        if current is None or current.context is not context or not current.is_alive():
            current = _admissions[id(context)] = Admission(context, p)
        current.policy = p
        return current


def admission_stats(context: zmq.Context[Any]) -> tuple[int, int, int]:
    """(admitted, refused for the key, refused for the cap) of `context`'s connections."""
    current = _admissions.get(id(context))
    if current is None or current.context is not context:
        return 0, 0, 0
    return current.admitted, current.refused_key, current.refused_cap
