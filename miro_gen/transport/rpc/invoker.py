"""The client side of remote calls: the `Invoker` that generated stubs call through ZeroMQ.

One DEALER socket per (thread, server endpoint): ZeroMQ sockets must stay in one thread, and a
thread waits for its own replies only. Sockets are set up so that failures are reported promptly
and never replayed (PITFALLS.md, ZeroMQ):

* `IMMEDIATE`: a request is only queued on a live connection; if none comes up within the
  connect time, or the server's host refuses the connection, the call fails with TRANSIENT
  (completed NO) and nothing is sent later;
* one connection per socket: it never reconnects by itself (`RECONNECT_IVL` -1), so its monitor
  gets each event at most once (made before the socket connects, never swapped, it loses
  none: a server killed while a call waits is always seen) and cannot fill up;
* ZMTP heartbeats, and that monitor: a server that dies or vanishes during a call gives
  COMM_FAILURE (completed MAYBE), at once for a killed process (its kernel closes the
  connection), within about a heartbeat timeout for a vanished host; never TIMEOUT;
* a request that finds its connection gone since the last call (nothing is sent) goes once
  more on a fresh connection: a server restarted at the same endpoint gets it;
* after a timeout or a failure the socket is closed with linger 0 and a fresh one is made for the
  next call, so a request the caller gave up on is never delivered to a restarted server.

A call is a send and a blocking receive with a time limit (checking the monitor every
`CHECK_INTERVAL` while the reply is late); request headers are built once per object and
operation. A reply body of `frames.ZERO_COPY_MIN` bytes or more is a read-only view over the
received frame (`frames.body_of`), so that the stub's decoding copies its octets once; a
process that sends or receives such bodies keeps megabyte buffers in its heap
(`transport.buffers`: glibc would return and re-fault them on every call).

A connection to a server on this host announces in its routing id that it takes large replies
in the server's shared memory (`rpc.shared`). A generated stub decodes such a reply's body in
place (the thread's lane holds the slot until its next call); any other caller gets it copied
out of the slot once, and the slot goes back to the server at once. A server that takes large
request bodies in its callers' shared memory says so in its own routing id, which a connection
learns with its first reply: from then on a request body of `shm.THRESHOLD` bytes or more goes
into this invoker's pool and a descriptor of it in the frame (in frames when no slot is free,
or again in frames when the server answers it could not read it).

Sockets come from `transport.sockets` (limits, heartbeats, CURVE): a request larger than the
maximum message size is MARSHAL before anything is sent, and a server that refuses the
handshake (no key, another key, too many connections) is TRANSIENT at once.
"""

from __future__ import annotations

import contextlib
import itertools
import struct
import threading
import time
from typing import Any, Protocol

import zmq
from zmq.backend import Socket as _Socket

from miro_gen.exceptions import COMM_FAILURE, MARSHAL, TIMEOUT, TRANSIENT, CompletionStatus
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime import views
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Reply, ReplyStatus, Servant, decoded_at_once
from miro_gen.transport import shm, sockets
from miro_gen.transport.buffers import keep_large_buffers
from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.shared import (
    BodyPool,
    SharedReplies,
    is_unreadable,
    routing_id,
    takes_requests,
)

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

CONNECT_TIMEOUT = 2.0  # seconds a call waits for a connection before TRANSIENT
# The minor code of a TRANSIENT for a connection refused at the handshake (no key, or the
# socket's connection cap): the peer runs, but will not have this process.
REFUSED_MINOR = 0x4D470001
CHECK_INTERVAL_MS = 250  # while waiting for a reply, how often to look for a lost connection
MAX_TAILS = 4096  # request header tails kept (objects x operations); then start again

_send, _recv, _set = _Socket.send, _Socket.recv, _Socket.set  # without pyzmq's Python wrappers
_NOBLOCK = int(zmq.NOBLOCK)
_MORE = int(zmq.SNDMORE) | _NOBLOCK
_RCVTIMEO = int(zmq.RCVTIMEO)
_CONNECTED = int(zmq.EVENT_HANDSHAKE_SUCCEEDED)
_DENIED = int(  # the server would not have us: no key, another key, too many connections
    zmq.EVENT_HANDSHAKE_FAILED_AUTH
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
    | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
)
_LOST = int(zmq.EVENT_DISCONNECTED)
# Before a connection: the one attempt ends closed (refused, or cut during the handshake).
_CLOSED = int(zmq.EVENT_CLOSED | zmq.EVENT_CONNECT_RETRIED)
# Each comes at most once in a socket's life: it never reconnects (RECONNECT_IVL -1), so the
# monitor, read only during calls, cannot fill up (libzmq's I/O thread would block on it).
_EVENTS = _CONNECTED | _DENIED | _LOST | _CLOSED
_RECONNECT_STOP = 109  # libzmq 4.3's ZMQ_RECONNECT_STOP (a draft name in pyzmq)
_STOP_AFTER_HANDSHAKE_FAILED = 2  # ZMQ_RECONNECT_STOP_HANDSHAKE_FAILED
_EVENT = struct.Struct("=HI")  # a monitor message's first frame: event, value
_OK = ReplyStatus.OK


class _Connection:
    """A DEALER socket to one endpoint, connected once (it never reconnects: a lost
    connection means a fresh socket), and the monitor that tells how that connection goes."""

    def __init__(self, context: zmq.Context[Any], endpoint: str) -> None:
        self.endpoint = endpoint
        self.socket = sockets.connecting_socket(context, zmq.DEALER)
        s = self.socket
        identity = routing_id(endpoint)  # large replies in shared memory, on this host
        if identity is not None:
            s.setsockopt(zmq.ROUTING_ID, identity)
        # Whether the server takes large request bodies in this caller's pool: not known
        # before its first reply (its routing id, from the handshake); never off this host.
        self.takes_requests: bool | None = None if identity is not None else False
        s.setsockopt(zmq.IMMEDIATE, 1)
        s.setsockopt(zmq.RECONNECT_IVL, -1)
        with contextlib.suppress(zmq.ZMQError):  # denied (no key, the cap): do not retry
            s.setsockopt(_RECONNECT_STOP, _STOP_AFTER_HANDSHAKE_FAILED)
        s.setsockopt(zmq.RCVTIMEO, CHECK_INTERVAL_MS)
        self.rcvtimeo = CHECK_INTERVAL_MS
        self.monitor = sockets.monitor(s, _EVENTS)
        s.connect(endpoint)
        self.connected = False
        self.refused = False
        self.denied = False
        self.lost = False

    def read_monitor(self) -> None:
        while True:
            try:
                event, _ = _EVENT.unpack_from(self.monitor.recv_multipart(zmq.NOBLOCK)[0])
            except zmq.Again:
                return
            except struct.error:  # pragma: no cover - libzmq sends well-formed events
                continue
            if event == _CONNECTED:
                self.connected = True
            elif self.connected:
                if event & (_LOST | _CLOSED):
                    self.lost = True
            elif event & _DENIED:
                self.denied = self.refused = True
            elif event & _CLOSED:
                self.refused = True

    def wait_connected(self, deadline: float) -> bool:
        while not self.connected and not self.refused:
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            if self.monitor.poll(int(left * 1000) + 1):
                self.read_monitor()
        return self.connected

    def set_rcvtimeo(self, ms: int) -> None:
        if ms != self.rcvtimeo:
            _set(self.socket, _RCVTIMEO, ms)
            self.rcvtimeo = ms

    def close(self) -> None:
        with contextlib.suppress(zmq.ZMQError):
            self.socket.disable_monitor()
        self.monitor.close(0)
        self.socket.close(0)


class LocalServants(Protocol):
    """Where a process serves the servants it passes as arguments: its object adapter."""

    def reference_for(self, servant: Servant) -> ObjectRef: ...


class ZmqInvoker:
    """Delivers requests to remote objects over ZeroMQ; safe to use from any thread. Local
    servants passed as arguments are activated on `adapter` (the process's server side)."""

    def __init__(
        self, context: zmq.Context[Any] | None = None, adapter: LocalServants | None = None
    ) -> None:
        self.context = context if context is not None else zmq.Context.instance()
        self.adapter = adapter
        self._local = threading.local()
        self._ids = itertools.count(1)
        self._tails: dict[tuple[bytes, str], bytes] = {}
        self._all: set[_Connection] = set()
        self._lock = threading.Lock()
        self._closed = False
        self.shared = SharedReplies()  # servers' pools of large replies, mapped
        self.requests: BodyPool | None = None  # this caller's pool of large requests, once used

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
        endpoint = ref.endpoint
        self.shared.give_back()  # the slot of this thread's last reply, decoded by now
        if self._closed:
            raise TRANSIENT("the invoker is closed")
        if not endpoint:
            raise TRANSIENT("the object reference has no endpoint (nil reference?)")
        limit = sockets.policy(self.context).max_message_size
        if len(body) > limit:  # the server would drop the connection: say why instead
            raise MARSHAL(
                f"{operation}: the request is {len(body)} bytes, more than the maximum message "
                f"size ({limit}; --max-message-size)",
                completed=CompletionStatus.NO,
            )
        wait = timeout if timeout is not None and timeout > 0 else 0.0
        start = time.monotonic()
        try:
            conn: _Connection = self._local.conns[endpoint]
        except (AttributeError, KeyError):
            conn = self._connection(endpoint)
        if not conn.connected:
            self._connect(conn, operation, start + wait if wait else start + CONNECT_TIMEOUT)
        tail = self._tails.get((ref.key, operation))
        if tail is None:
            tail = self._tail(ref.key, operation)
        request_id = next(self._ids)
        descriptor = None
        if conn.takes_requests and not oneway and len(body) >= shm.THRESHOLD:
            descriptor = self._put_request(body, limit)  # None: no free slot, in frames
        if descriptor is not None:
            header = frames.request_header(tail, request_id, int(wait * 1000), False, True)
            sent = _sent(conn.socket, header, descriptor)
        else:
            header = frames.request_header(tail, request_id, int(wait * 1000), oneway)
            sent = _sent(conn.socket, header, body)
        if not sent:
            # Nothing was sent: the connection was lost since the last call (its server was
            # stopped or killed). Once more on a fresh connection, which finds a server
            # restarted at the same endpoint, or fails as a refused one does; in frames (the
            # server there may not take shared memory; a slot written goes back at its lease).
            self._drop(conn)
            conn = self._connection(endpoint)
            self._connect(conn, operation, start + wait if wait else start + CONNECT_TIMEOUT)
            header = frames.request_header(tail, request_id, int(wait * 1000), oneway)
            descriptor = None
            if not _sent(conn.socket, header, body):
                self._drop(conn)
                raise TRANSIENT(f"cannot send {operation} to {endpoint}")
        if oneway:
            return None
        if wait and wait * 1000 < conn.rcvtimeo:
            conn.set_rcvtimeo(int(wait * 1000) + 1)
        reply = self._await(conn, request_id, operation, start + wait if wait else float("inf"))
        if descriptor is not None and is_unreadable(reply):
            # The server could not read the body in this caller's pool (nothing ran): in
            # frames from now on, this call again first.
            conn.takes_requests = False
            return self.invoke(ref, operation, body, timeout=timeout)
        return reply

    def _put_request(self, body: bytes, limit: int) -> bytes | None:
        """`body` written into a free slot of this caller's pool (mapped at its first large
        request): the descriptor to send instead; None when no slot is free."""
        pool = self.requests
        if pool is None:
            with self._lock:
                pool = self.requests
                if pool is None:
                    pool = self.requests = BodyPool(limit, name="miro-requests")
        return pool.put(body if type(body) is bytes else bytes(body))  # (any buffer, by hand)

    def _connect(self, conn: _Connection, operation: str, deadline: float) -> None:
        """Wait for the connection's handshake until `deadline` (or the connect timeout);
        TRANSIENT (completed NO: nothing was sent) when it is refused or does not come."""
        if not conn.wait_connected(min(deadline, time.monotonic() + CONNECT_TIMEOUT)):
            self._drop(conn)
            if conn.denied:
                raise TRANSIENT(
                    f"{conn.endpoint} refused the connection for {operation}: it needs the "
                    "robot's or fleet's key (--keys), or has too many connections",
                    REFUSED_MINOR,
                )
            why = "connection refused" if conn.refused else "no connection in time"
            raise TRANSIENT(f"cannot reach {conn.endpoint} for {operation}: {why}")

    def reference_for(self, servant: Servant) -> ObjectRef:
        if self.adapter is None:
            raise TRANSIENT("a local object can only be passed by a process that serves objects")
        return self.adapter.reference_for(servant)

    # ---- internals ------------------------------------------------------------------------------

    def _await(self, conn: _Connection, request_id: int, operation: str, deadline: float) -> Reply:
        """The reply to `request_id`: a blocking receive, interrupted every CHECK_INTERVAL to
        look for a lost connection and the deadline."""
        sock = conn.socket
        while True:
            try:
                frame = _recv(sock, 0, False)
                if conn.takes_requests is None:  # the server's routing id, from the handshake
                    conn.takes_requests = _takes_requests(frame)
                parts: list[bytes | memoryview] = [frame.bytes]
                while frame.more:
                    frame = _recv(sock, _NOBLOCK, False)
                    parts.append(frames.body_of(frame))
            except zmq.Again:
                self._check(conn, operation, deadline)
                continue
            if type(parts[-1]) is memoryview:  # a large body: keep such buffers in the heap
                keep_large_buffers()
            if len(parts) == 2 and frames.ok_reply_id(parts[0]) == request_id:
                if conn.rcvtimeo != CHECK_INTERVAL_MS:
                    conn.set_rcvtimeo(CHECK_INTERVAL_MS)
                return Reply(_OK, parts[1])  # the common case
            if len(parts) == 2 and frames.shared_reply_id(parts[0]) == request_id:
                if conn.rcvtimeo != CHECK_INTERVAL_MS:
                    conn.set_rcvtimeo(CHECK_INTERVAL_MS)
                keep_large_buffers()
                # In place for a stub that decodes it at once (the slot held until this
                # thread's next call); else a view of a copy (octet_views: views of that).
                in_place = decoded_at_once() and not getattr(views.active, "on", False)
                limit = sockets.policy(self.context).max_message_size  # as for a frame
                body = self.shared.body(bytes(parts[1]), operation, in_place, limit)
                return Reply(_OK, body if type(body) is memoryview else memoryview(body))
            reply = self._other_reply(conn, parts, request_id)
            if reply is not None:
                if conn.rcvtimeo != CHECK_INTERVAL_MS:
                    conn.set_rcvtimeo(CHECK_INTERVAL_MS)
                return reply

    def _check(self, conn: _Connection, operation: str, deadline: float) -> None:
        """No reply yet: COMM_FAILURE if the connection is lost, TIMEOUT past `deadline`."""
        conn.read_monitor()
        if conn.lost:
            self._drop(conn)
            raise COMM_FAILURE(
                f"{operation}: lost the connection to {conn.endpoint}",
                completed=CompletionStatus.MAYBE,
            )
        left = deadline - time.monotonic()
        if left <= 0:
            self._drop(conn)
            raise TIMEOUT(
                f"{operation}: no reply from {conn.endpoint} in time",
                completed=CompletionStatus.MAYBE,
            )
        # (a call without a time limit has an infinite deadline: no int of that)
        conn.set_rcvtimeo(
            CHECK_INTERVAL_MS if left * 1000 >= CHECK_INTERVAL_MS else int(left * 1000) + 1
        )

    def _other_reply(
        self, conn: _Connection, parts: list[bytes | memoryview], request_id: int
    ) -> Reply | None:
        """A message that is not an ok reply to `request_id`: an exception reply to it, or
        None (a late reply to an earlier call, or a malformed one: logged and dropped)."""
        if len(parts) != 2:
            _peer_warnings.warning(
                "dropped a reply of %d frames from %s", len(parts), conn.endpoint
            )
            return None
        try:
            head = frames.decode_reply(parts[0])
        except frames.FrameError as e:
            _peer_warnings.warning("dropped a reply from %s: %s", conn.endpoint, e)
            return None
        if head.request_id != request_id:  # a late reply to an earlier call
            return None
        return Reply(ReplyStatus(head.status), parts[1], head.repo_id)

    def _tail(self, key: bytes, operation: str) -> bytes:
        if len(self._tails) >= MAX_TAILS:
            self._tails.clear()
        tail = self._tails[(key, operation)] = frames.request_tail(key, operation)
        return tail

    def _connection(self, endpoint: str) -> _Connection:
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
        self.shared.sweep()  # its server may be gone: unmap its pool of replies

    def close(self) -> None:
        """Close every socket (of every thread); calls after this fail with TRANSIENT."""
        self._closed = True
        with self._lock:
            conns, self._all = self._all, set()
        for conn in conns:
            conn.close()
        self.shared.close()
        if self.requests is not None:
            self.requests.close()


def _takes_requests(frame: zmq.Frame) -> bool:
    """Whether the server a frame came from takes large request bodies in shared memory."""
    try:
        return takes_requests(str(frame.get("Identity")))
    except zmq.ZMQError:  # no routing id: a server of an older version
        return False


def _sent(sock: zmq.Socket[Any], header: bytes, body: bytes) -> bool:
    """Send a request's two frames; False when the socket has no connection to take them
    (ZMQ_IMMEDIATE: then nothing is queued)."""
    try:
        _send(sock, header, _MORE)
        if len(body) < frames.ZERO_COPY_MIN:
            _send(sock, body, _NOBLOCK)
        else:  # a large request goes without a copy
            keep_large_buffers()
            _send(sock, body, _NOBLOCK, False)
    except zmq.ZMQError:
        return False
    return True
