"""Admission: the ZAP handler (ZeroMQ RFC 27) of a context, in a thread of its own.

libzmq asks it about every connection to a listening socket (one made by
`sockets.listening_socket`, which names the socket's ZAP domain) before the first message
passes. It answers no when

* CURVE is on and the client's long-term public key is not the robot's or fleet's key (only a
  process holding the secret key can complete the handshake with that public key), or
* the socket already has `max_connections` connections: libzmq has no connection cap of its
  own, so this thread counts them from the socket's monitor (accepted minus disconnected).

Answers take microseconds; the thread never calls into Python code of the services. Counters
(`admitted`, `refused_key`, `refused_cap`) are for tests and benchmarks.
"""

from __future__ import annotations

import contextlib
import itertools
import queue
import threading
import time
from typing import Any

import zmq
from zmq.utils import z85
from zmq.utils.monitor import parse_monitor_message

from miro_gen.log import logger
from miro_gen.transport.sockets import SocketPolicy

_log = logger("MIRO")

ZAP_ENDPOINT = "inproc://zeromq.zap.01"
_EVENTS = zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED | zmq.EVENT_MONITOR_STOPPED
_NOTICE_EVERY = 10.0  # seconds between two warnings about refused connections
_ids = itertools.count(1)


class Admission(threading.Thread):
    """The ZAP handler of one context."""

    def __init__(self, context: zmq.Context[Any], policy: SocketPolicy) -> None:
        super().__init__(name="miro-admission", daemon=True)
        self.context = context
        self.policy = policy
        self.admitted = 0
        self.refused_key = 0
        self.refused_cap = 0
        self._new: queue.SimpleQueue[tuple[bytes, zmq.Socket[Any]]] = queue.SimpleQueue()
        self._live: dict[bytes, set[int]] = {}  # domain -> descriptors of its connections
        self._monitors: dict[zmq.Socket[Any], bytes] = {}
        self._stopping = False
        self._noticed = 0.0
        self._ready = threading.Event()
        self._zap: zmq.Socket[Any] | None = None
        self.start()
        self._ready.wait(5)

    def watch(self, socket: zmq.Socket[Any]) -> None:
        """Admit connections to `socket` (a listening socket, before it binds). Call from the
        socket's thread: its monitor is made there and handed over to this one."""
        domain = f"miro-{next(_ids)}".encode()
        socket.setsockopt(zmq.ZAP_DOMAIN, domain)
        monitor = socket.get_monitor_socket(_EVENTS)
        self._new.put((domain, monitor))

    def stop(self) -> None:
        self._stopping = True
        self.join(2)

    # ---- the thread ---------------------------------------------------------------------------

    def run(self) -> None:
        try:
            zap = self._zap = self.context.socket(zmq.REP)
            zap.setsockopt(zmq.LINGER, 0)
            zap.bind(ZAP_ENDPOINT)
        except zmq.ZMQError as e:  # another ZAP handler owns this context
            _log.error("cannot admit connections: %s", e)
            self._ready.set()
            return
        self._ready.set()
        poller = zmq.Poller()
        poller.register(zap, zmq.POLLIN)
        try:
            while not self._stopping:
                self._take_new(poller)
                for socket, _ in poller.poll(100):
                    if socket is zap:
                        self._answer(zap, poller)
                    else:
                        self._read_monitor(socket, poller)
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
                event = parse_monitor_message(monitor.recv_multipart(zmq.NOBLOCK))
            except zmq.Again:
                return
            kind, fd = event["event"], int(event["value"])
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
        status, text = b"200", b"OK"
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
        zap.send_multipart([b"1.0", request_id, status, text, b"", b""])
        if status != b"200":
            now = time.monotonic()
            if now - self._noticed >= _NOTICE_EVERY:
                self._noticed = now
                _log.warning(
                    "refused a connection from %s: %s",
                    address.decode(errors="replace"),
                    text.decode(),
                )


_admissions: dict[int, Admission] = {}
_lock = threading.Lock()


def admission(context: zmq.Context[Any], policy: SocketPolicy) -> Admission:
    """The admission thread of `context`, started on first use (with `policy`; a later
    policy of the context replaces it for the connections that follow)."""
    with _lock:
        current = _admissions.get(id(context))
        if current is None or not current.is_alive() or current.context is not context:
            current = _admissions[id(context)] = Admission(context, policy)
        current.policy = policy
        return current


def stop_admission(context: zmq.Context[Any]) -> None:
    with _lock:
        current = _admissions.pop(id(context), None)
    if current is not None and current.context is context:
        with contextlib.suppress(RuntimeError):
            current.stop()


def stats(context: zmq.Context[Any]) -> tuple[int, int, int]:
    """(admitted, refused for the key, refused for the cap) of `context`'s connections."""
    current = _admissions.get(id(context))
    if current is None:
        return 0, 0, 0
    return current.admitted, current.refused_key, current.refused_cap
