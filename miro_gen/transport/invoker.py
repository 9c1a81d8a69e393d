"""The client side of remote calls: the `Invoker` that generated stubs call through ZeroMQ.

One DEALER socket per (thread, server endpoint): ZeroMQ sockets must stay in one thread, and a
thread waits for its own replies only. Sockets are set up so that failures are reported promptly
and never replayed (PITFALLS.md, ZeroMQ):

* `IMMEDIATE`: a request is only queued on a live connection; if none comes up within the
  connect time, the call fails with TRANSIENT (completed NO) and nothing is sent later;
* ZMTP heartbeats, and a socket monitor: a server that dies or vanishes during a call gives
  COMM_FAILURE (completed MAYBE) within about a heartbeat timeout;
* after a timeout or a failure the socket is closed with linger 0 and a fresh one is made for the
  next call, so a request the caller gave up on is never delivered to a restarted server.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time
from typing import Any

import zmq
from zmq.utils.monitor import parse_monitor_message

from miro_gen.exceptions import COMM_FAILURE, MARSHAL, TIMEOUT, TRANSIENT, CompletionStatus
from miro_gen.log import logger
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Reply, ReplyStatus, Servant
from miro_gen.transport import frames, sockets

_log = logger("MIRO")

CONNECT_TIMEOUT = 2.0  # seconds a call waits for a connection before TRANSIENT
# Only events that come once per connection: a monitor that nobody reads (the socket of a
# thread that made one call long ago) must not fill up, or libzmq's I/O thread blocks sending
# to it (a failed reconnection to a dead server would give an event every RECONNECT_IVL).
_LOST = zmq.EVENT_DISCONNECTED
_RECONNECT_STOP = 109  # libzmq 4.3's ZMQ_RECONNECT_STOP (a draft name in pyzmq)
_STOP_AFTER_HANDSHAKE_FAILED = 2  # ZMQ_RECONNECT_STOP_HANDSHAKE_FAILED
_REFUSED = (  # the server would not have us: no key, another key, or too many connections
    zmq.EVENT_HANDSHAKE_FAILED_AUTH
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
    | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
)


class _Connection:
    """A DEALER socket to one endpoint, and the monitor that tells when its peer is lost."""

    def __init__(self, context: zmq.Context[Any], endpoint: str) -> None:
        self.endpoint = endpoint
        self.socket = sockets.connecting_socket(context, zmq.DEALER)
        s = self.socket
        s.setsockopt(zmq.IMMEDIATE, 1)
        s.setsockopt(zmq.RECONNECT_IVL, 100)
        s.setsockopt(zmq.RECONNECT_IVL_MAX, 2000)
        with contextlib.suppress(zmq.ZMQError):  # refused (no key, the cap): do not retry
            s.setsockopt(_RECONNECT_STOP, _STOP_AFTER_HANDSHAKE_FAILED)
        self.monitor = sockets.monitor(s, zmq.EVENT_HANDSHAKE_SUCCEEDED | _LOST | _REFUSED)
        s.connect(endpoint)
        self.connected = False
        self.lost = False
        self.refused = False
        self.poller = zmq.Poller()
        self.poller.register(s, zmq.POLLIN)
        self.poller.register(self.monitor, zmq.POLLIN)

    def read_monitor(self) -> None:
        while True:
            try:
                event = parse_monitor_message(self.monitor.recv_multipart(zmq.NOBLOCK))
            except zmq.Again:
                return
            if event["event"] == zmq.EVENT_HANDSHAKE_SUCCEEDED:
                self.connected = True
            elif event["event"] & _LOST and self.connected:
                self.lost = True
            elif event["event"] & _REFUSED:
                self.refused = True

    def wait_connected(self, deadline: float) -> bool:
        while not self.connected:
            left = deadline - time.monotonic()
            if left <= 0 or self.refused:
                return False
            if self.monitor.poll(int(left * 1000) + 1):
                self.read_monitor()
        return True

    def close(self) -> None:
        with contextlib.suppress(zmq.ZMQError):
            self.socket.disable_monitor()
        self.monitor.close(0)
        self.socket.close(0)


class ZmqInvoker:
    """Delivers requests to remote objects over ZeroMQ; safe to use from any thread. Local
    servants passed as arguments are activated on `adapter` (the process's server side)."""

    def __init__(self, context: zmq.Context[Any] | None = None, adapter: Any = None) -> None:
        self.context = context if context is not None else zmq.Context.instance()
        self.adapter = adapter
        self._local = threading.local()
        self._ids = itertools.count(1)
        self._all: set[_Connection] = set()
        self._lock = threading.Lock()
        self._closed = False

    # ---- Invoker protocol -----------------------------------------------------------------------

    def invoke(
        self,
        ref: ObjectRef,
        operation: str,
        body: bytes,
        *,
        oneway: bool = False,
        timeout: float | None = None,
    ) -> Reply | None:
        if not ref.endpoint:
            raise TRANSIENT("the object reference has no endpoint (nil reference?)")
        limit = sockets.policy(self.context).max_message_size
        if len(body) > limit:  # the server would drop the connection: say why instead
            raise MARSHAL(
                f"{operation}: the request is {len(body)} bytes, more than the maximum message "
                f"size ({limit}; --max-message-size)",
                completed=CompletionStatus.NO,
            )
        wait = 0.0 if timeout is None else max(0.0, timeout)
        started = time.monotonic()
        deadline = started + wait if wait else float("inf")
        conn = self._connection(ref.endpoint)
        if not conn.wait_connected(min(deadline, started + CONNECT_TIMEOUT)):
            self._drop(conn)
            if conn.refused:
                raise TRANSIENT(
                    f"{ref.endpoint} refused the connection for {operation}: it needs the "
                    "robot's or fleet's key (--keys), or has too many connections"
                )
            raise TRANSIENT(f"cannot reach {ref.endpoint} for {operation}")
        request_id = next(self._ids)
        header = frames.encode_request(
            frames.Request(request_id, ref.key, operation, int(wait * 1000), oneway)
        )
        try:
            conn.socket.send_multipart([header, body], zmq.NOBLOCK)
        except zmq.Again:
            self._drop(conn)
            raise TRANSIENT(f"cannot send {operation} to {ref.endpoint}") from None
        if oneway:
            return None
        return self._await(conn, request_id, operation, deadline)

    def reference_for(self, servant: Servant) -> ObjectRef:
        if self.adapter is None:
            raise TRANSIENT("a local object can only be passed by a process that serves objects")
        ref: ObjectRef = self.adapter.reference_for(servant)
        return ref

    # ---- internals ------------------------------------------------------------------------------

    def _await(self, conn: _Connection, request_id: int, operation: str, deadline: float) -> Reply:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self._drop(conn)
                raise TIMEOUT(
                    f"{operation}: no reply from {conn.endpoint} in time",
                    completed=CompletionStatus.MAYBE,
                )
            wait_ms = -1 if left == float("inf") else min(int(left * 1000) + 1, 2**31 - 1)
            events = dict(conn.poller.poll(wait_ms))
            if conn.monitor in events:
                conn.read_monitor()
                if conn.lost:
                    self._drop(conn)
                    raise COMM_FAILURE(
                        f"{operation}: lost the connection to {conn.endpoint}",
                        completed=CompletionStatus.MAYBE,
                    )
            if conn.socket in events:
                reply = self._receive(conn, request_id)
                if reply is not None:
                    return reply

    def _receive(self, conn: _Connection, request_id: int) -> Reply | None:
        while True:
            try:
                parts = conn.socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return None
            if len(parts) != 2:
                _log.warning("dropped a reply of %d frames from %s", len(parts), conn.endpoint)
                continue
            try:
                head = frames.decode_reply(parts[0])
            except frames.FrameError as e:
                _log.warning("dropped a reply from %s: %s", conn.endpoint, e)
                continue
            if head.request_id != request_id:  # a late reply to an earlier call
                continue
            return Reply(ReplyStatus(head.status), parts[1], head.repo_id)

    def _connection(self, endpoint: str) -> _Connection:
        if self._closed:
            raise TRANSIENT("the invoker is closed")
        conns: dict[str, _Connection] | None = getattr(self._local, "conns", None)
        if conns is None:
            conns = self._local.conns = {}
        conn = conns.get(endpoint)
        if conn is None:
            conn = conns[endpoint] = _Connection(self.context, endpoint)
            with self._lock:
                self._all.add(conn)
        return conn

    def _drop(self, conn: _Connection) -> None:
        conns: dict[str, _Connection] = getattr(self._local, "conns", {})
        if conns.get(conn.endpoint) is conn:
            del conns[conn.endpoint]
        with self._lock:
            self._all.discard(conn)
        conn.close()

    def close(self) -> None:
        """Close every socket (of every thread); calls after this fail with TRANSIENT."""
        self._closed = True
        with self._lock:
            conns, self._all = self._all, set()
        for conn in conns:
            conn.close()
