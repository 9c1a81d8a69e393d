"""The IIOP server's connections, all read and written by one thread (a `selectors` loop).

A connection costs a socket, a buffer and a few objects: never a thread. The loop accepts,
reads each ready connection a chunk at a time (so a large message does not hold up the small
ones of others) into whole messages (`inbound.Inbound`, under the server's `Budget`), hands them
to the server, and writes what could not be sent at once. What bounds it:

* **connections**: at most `max_connections`. Beyond, room is made by closing the connection
  heard from least recently among those with no request running and no reply to send (an
  idle one, or one silent part-way through a message), with a CloseConnection, which GIOP
  clients answer by reconnecting when they next call; when there is none, the new connection
  is closed so. A flood of connections thus pushes out its own, and a caller gets in. A
  connection silent for `stall` seconds part-way through a message, or that has not taken a
  byte of its replies for as long, is closed.
* **descriptors**: when `accept` fails for want of descriptors (EMFILE and its kin), room is
  made the same way; when there is none, accepting pauses, for 50 ms doubling up to 1 s,
  instead of asking again at once (the listening socket stays ready, so a loop that asked
  again would spin).
* **memory**: the budget; a connection with `MAX_RUNNING` requests in hand, or more than
  `OUT_LIMIT` bytes of replies it has not read, is not read until that changes.

Replies are sent by whichever thread made them, straight away when the socket takes them (no
hand-off); what it does not take is queued for the loop, which the thread wakes.
"""

from __future__ import annotations

import contextlib
import errno
import os
import selectors
import socket
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable

from miro_gen.corba import giop
from miro_gen.corba.connection import NotGiop
from miro_gen.corba.giop import GiopError, MsgType
from miro_gen.corba.inbound import Budget, Inbound, Message, Refused
from miro_gen.log import PeerWarnings, logger

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers cause: rate-limited, with counts

MAX_RUNNING = 64  # requests of one connection in hand (waiting or running) before it is not read
OUT_LIMIT = 1 << 20  # bytes of replies a connection has not taken before it is not read
STALL = 15.0  # seconds a connection may be silent part-way through a message (or not read)
_ACCEPTS = 64  # connections accepted in one turn of the loop
_BACKOFF = (0.05, 1.0)  # seconds accepting pauses when descriptors run out: first, at most
_OUT_OF_DESCRIPTORS = {errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM}


class ServerConnection:
    """One client's connection, as the loop and the server's workers share it."""

    def __init__(self, sock: socket.socket, peer: str, inbound: Inbound) -> None:
        self.sock = sock
        self.peer = peer  # HOST:PORT, for messages
        self.inbound = inbound
        self.lock = threading.Lock()  # sending and closing
        self.out: deque[memoryview] = deque()
        self.out_bytes = 0
        self.running = 0  # messages handed to the server and not yet done with
        self.cancelled: set[int] = set()  # request ids a CancelRequest named
        self.progress = time.monotonic()  # when a byte last went either way
        self.closed = False
        self.broken = False  # a worker found it gone: the loop closes it
        self.mask = 0  # the events the loop waits for on it
        # Who is at the other end, as a servant that checks its callers worked it out (the
        # naming service's principal of the caller), kept for the connection's next requests.
        self.identity: object | None = None

    def addresses(self) -> tuple[tuple[str, int], tuple[str, int]] | None:
        """(the peer's address, ours) as (host, port) pairs; None when they cannot be had
        (the socket closed, or not TCP)."""
        try:
            peer, here = self.sock.getpeername(), self.sock.getsockname()
        except OSError:
            return None
        if not isinstance(peer, tuple) or not isinstance(here, tuple):
            return None
        return (str(peer[0]), int(peer[1])), (str(here[0]), int(here[1]))

    @property
    def evictable(self) -> bool:
        """Whether closing it loses no call: no request of it running, no reply to send."""
        return not (self.running or self.out_bytes)


Handler = Callable[[ServerConnection, "Message | Refused"], bool]


class ConnectionLoop:
    """Accepts on `listener` and serves its connections in a thread of its own; `handler(conn,
    item)` gets each whole message (or refusal) on that thread and returns False when the
    connection is to be closed. Every `Message` it gets must be given back with `done`."""

    def __init__(
        self,
        listener: socket.socket,
        handler: Handler,
        budget: Budget,
        max_message: int,
        max_connections: int,
        stall: float = STALL,
    ) -> None:
        self.listener = listener
        self.handler = handler
        self.budget = budget
        self.max_message = max_message
        self.max_connections = max_connections
        self.stall = stall
        self.refused = 0  # connections closed at once, for want of room (for tests, benches)
        self.evicted = 0  # connections closed to make room
        self.out_of_descriptors = 0  # times accept failed for want of descriptors
        self._conns: OrderedDict[ServerConnection, None] = OrderedDict()  # least recent first
        self._selector = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._changed: deque[ServerConnection] = deque()
        self._closing = False
        self._backoff = 0.0
        self._accept_at: float | None = None  # when accepting resumes, while paused
        listener.setblocking(False)
        self._selector.register(listener, selectors.EVENT_READ)
        self._selector.register(self._wake_r, selectors.EVENT_READ)
        self._thread = threading.Thread(target=self._run, name="miro-iiop-io", daemon=True)
        self._thread.start()

    @property
    def connections(self) -> int:
        return len(self._conns)

    # ---- from any thread ------------------------------------------------------------------------

    def send(self, conn: ServerConnection, data: bytes) -> None:
        """Send `data` on `conn`: at once as far as the socket takes it, the rest queued."""
        queued = False
        with conn.lock:
            if conn.closed or conn.broken:
                return
            if conn.out:
                conn.out.append(memoryview(data))
                sent = 0
            else:
                try:
                    sent = conn.sock.send(data)
                except BlockingIOError:
                    sent = 0
                except OSError:
                    conn.broken = True
                    sent = len(data)
                if sent < len(data):
                    conn.out.append(memoryview(data)[sent:])
            if sent < len(data):
                conn.out_bytes += len(data) - sent
                self.budget.force(len(data) - sent)
                queued = True
            else:
                conn.progress = time.monotonic()
        if queued or conn.broken:
            self._changed_from_outside(conn)

    def done(self, conn: ServerConnection, charge: int) -> None:
        """The server is done with a message of `conn` that reserved `charge` bytes."""
        self.budget.give(charge)
        with conn.lock:
            conn.running -= 1
            wake = conn.running == MAX_RUNNING - 1
        if wake:
            self._changed_from_outside(conn)

    def close(self) -> None:
        """Stop: CloseConnection to every client, every socket closed, the thread ended."""
        self._closing = True
        self._wake()
        if threading.current_thread() is not self._thread:
            self._thread.join(10)

    def _changed_from_outside(self, conn: ServerConnection) -> None:
        if threading.current_thread() is self._thread:
            self._update(conn)
        else:
            self._changed.append(conn)
            self._wake()

    def _wake(self) -> None:
        with contextlib.suppress(OSError):  # full: it is awake already; closed: it has ended
            self._wake_w.send(b"\0")

    # ---- the loop -------------------------------------------------------------------------------

    def _run(self) -> None:
        last_scan = time.monotonic()
        try:
            while not self._closing:
                timeout = 1.0
                if self._accept_at is not None:
                    timeout = max(0.0, min(timeout, self._accept_at - time.monotonic()))
                for key, events in self._selector.select(timeout):
                    self._event(key, events)
                while self._changed:
                    self._update(self._changed.popleft())
                now = time.monotonic()
                if self._accept_at is not None and now >= self._accept_at:
                    self._accept_at = None
                    self._selector.register(self.listener, selectors.EVENT_READ)
                if now - last_scan >= 1.0:
                    last_scan = now
                    self._close_stalled(now)
        except Exception:  # a defect of ours: said, and the server stops serving
            _log.exception("IIOP: the connection loop failed")
        finally:
            self._shut()

    def _event(self, key: selectors.SelectorKey, events: int) -> None:
        conn = key.data
        if isinstance(conn, ServerConnection):
            if events & selectors.EVENT_WRITE:
                self._flush(conn)
            if events & selectors.EVENT_READ and not conn.closed:
                self._read(conn)
        elif key.fileobj is self.listener:
            self._accept()
        else:
            with contextlib.suppress(OSError):
                self._wake_r.recv(4096)

    def _update(self, conn: ServerConnection) -> None:
        """Wait for the events `conn` now wants (nothing to read while it has too much in
        hand); close it if a worker found it broken."""
        if conn.closed:
            return
        if conn.broken:
            self._close(conn)
            return
        mask = 0
        if conn.running < MAX_RUNNING and conn.out_bytes <= OUT_LIMIT:
            mask |= selectors.EVENT_READ
        if conn.out_bytes:
            mask |= selectors.EVENT_WRITE
        if mask == conn.mask:
            return
        if conn.mask == 0:
            self._selector.register(conn.sock, mask, conn)
        elif mask == 0:
            self._selector.unregister(conn.sock)
        else:
            self._selector.modify(conn.sock, mask, conn)
        conn.mask = mask

    # ---- accepting ------------------------------------------------------------------------------

    def _accept(self) -> None:
        for _ in range(_ACCEPTS):
            try:
                sock, addr = self.listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as e:
                if e.errno not in _OUT_OF_DESCRIPTORS:
                    continue  # the client gave up meanwhile (ECONNABORTED, ...)
                self.out_of_descriptors += 1
                if self._evict("this process has no file descriptor left"):
                    continue
                self._pause_accepting(e)
                return
            self._backoff = 0.0
            peer = f"{addr[0]}:{addr[1]}"
            if len(self._conns) >= self.max_connections and not self._evict(
                f"{self.max_connections} connections are open"
            ):
                self.refused += 1
                _peer_warnings.warning(
                    "IIOP: refused a connection from %s: %d connections are open, all with calls "
                    "in hand (%d refused so far)",
                    peer, len(self._conns), self.refused, key="iiop-cap"
                )  # fmt: skip
                with contextlib.suppress(OSError):
                    sock.setblocking(False)
                    sock.send(giop.encode_simple(2, MsgType.CLOSE_CONNECTION))
                sock.close()
                continue
            self._add(sock, peer)

    def _add(self, sock: socket.socket, peer: str) -> None:
        sock.setblocking(False)
        with contextlib.suppress(OSError):  # not TCP (a Unix socket in a test)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = ServerConnection(sock, peer, Inbound(peer, self.max_message, self.budget))
        self._conns[conn] = None
        self._update(conn)
        self._read(conn)  # the request has usually come with the connection

    def _evict(self, why: str) -> bool:
        """Close the evictable connection heard from least recently (CloseConnection: its
        client reconnects when it next calls); False when there is none."""
        for conn in self._conns:
            if conn.evictable:
                self.evicted += 1
                _peer_warnings.warning(
                    "IIOP: %s: closing the connections heard from least recently to make room "
                    "(%d so far)",
                    why, self.evicted, key="iiop-evict"
                )  # fmt: skip
                self._close(conn, giop.encode_simple(2, MsgType.CLOSE_CONNECTION))
                return True
        return False

    def _pause_accepting(self, e: OSError) -> None:
        self._backoff = min(max(self._backoff * 2, _BACKOFF[0]), _BACKOFF[1])
        self._accept_at = time.monotonic() + self._backoff
        self._selector.unregister(self.listener)
        _peer_warnings.warning(
            "IIOP: cannot accept connections (%s) with %d open, all with calls in hand: "
            "pausing %.2f s",
            os.strerror(e.errno or 0), len(self._conns), self._backoff, key="iiop-fds"
        )  # fmt: skip

    # ---- reading and writing --------------------------------------------------------------------

    def _read(self, conn: ServerConnection) -> None:
        try:
            data = conn.sock.recv(conn.inbound.want())
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._close(conn)
            return
        if not data:
            self._close(conn)
            return
        conn.progress = time.monotonic()
        self._conns.move_to_end(conn)
        try:
            for item in conn.inbound.feed(data):
                if isinstance(item, Message):
                    with conn.lock:
                        conn.running += 1
                if not self.handler(conn, item):
                    self._close(conn)
                    return
        except NotGiop as e:
            _peer_warnings.warning("IIOP: %s; closing the connection", e)
            self._close(conn, None if e.zmq else giop.encode_simple(1, MsgType.MESSAGE_ERROR))
            return
        except GiopError as e:
            _peer_warnings.warning("IIOP: %s: %s; answered with MessageError", conn.peer, e)
            self._close(conn, giop.encode_simple(1, MsgType.MESSAGE_ERROR))
            return
        except Exception:  # a defect of ours: logged, and this connection only ends
            _log.exception("IIOP: cannot handle a message from %s", conn.peer)
            self._close(conn, giop.encode_simple(1, MsgType.MESSAGE_ERROR))
            return
        self._update(conn)

    def _flush(self, conn: ServerConnection) -> None:
        with conn.lock:
            while conn.out:
                chunk = conn.out[0]
                try:
                    sent = conn.sock.send(chunk)
                except BlockingIOError:
                    break
                except OSError:
                    conn.broken = True
                    break
                conn.progress = time.monotonic()
                conn.out_bytes -= sent
                self.budget.give(sent)
                if sent < len(chunk):
                    conn.out[0] = chunk[sent:]
                    break
                conn.out.popleft()
        self._update(conn)

    def _close_stalled(self, now: float) -> None:
        for conn in list(self._conns):
            if (conn.inbound.busy or conn.out_bytes) and now - conn.progress > self.stall:
                what = "part-way through a message" if conn.inbound.busy else "taking no reply"
                _peer_warnings.warning(
                    "IIOP: %s has been silent %s for %.0f s: closing the connection",
                    conn.peer, what, self.stall, key="iiop-stall"
                )  # fmt: skip
                self._close(conn)

    def _close(self, conn: ServerConnection, last: bytes | None = None) -> None:
        """Close `conn` (on the loop's thread), saying `last` first if the socket takes it."""
        with conn.lock:
            if conn.closed:
                return
            conn.closed = True
            if last is not None and not conn.out:
                with contextlib.suppress(OSError):
                    conn.sock.send(last)
            self.budget.give(conn.out_bytes)
            conn.out.clear()
            conn.out_bytes = 0
            if conn.mask:
                self._selector.unregister(conn.sock)
                conn.mask = 0
            with contextlib.suppress(OSError):
                conn.sock.shutdown(socket.SHUT_RDWR)
            conn.sock.close()
        conn.inbound.release()
        self._conns.pop(conn, None)

    def _shut(self) -> None:
        for conn in list(self._conns):
            self._close(conn, giop.encode_simple(2, MsgType.CLOSE_CONNECTION))
        with contextlib.suppress(KeyError, ValueError):
            self._selector.unregister(self.listener)
        self._selector.close()
        self.listener.close()
        self._wake_r.close()
        self._wake_w.close()
