"""The server side of IIOP: servants of generated skeletons, served to CORBA clients.

One listening socket per process. Its connections are read and written by one thread
(`server_io.ConnectionLoop`), whatever their number; a request runs on that thread when its
method is marked `@nonblocking`, else on a bounded worker pool (so that one connection may carry
several calls at once, as TAO multiplexes them), and the reply is sent when it is ready. What a
server holds is bounded (docs/SECURITY.md): the bytes of the requests it reads, holds and runs
(`inbound.Budget`: a request the budget has no room for is answered TRANSIENT without being
kept), fragments per connection, connections (`max_connections`; idle ones make room), requests
waiting for a worker (`MAX_WAITING`), threads (the loop and `workers`).

It listens on loopback unless `beyond_loopback`: IIOP has neither keys nor encryption, so
serving it to other machines is a choice the caller makes (`--insecure`), never a default
(`BeyondLoopback` otherwise).

Object keys are what the caller names them (`add_to_name_service` uses the full name,
`robot1/ExampleA`): with a fixed port, a restarted server publishes the very same IORs, as a
persistent POA does, and `corbaloc:iiop:HOST:PORT/robot1/ExampleA` reaches it.

A message that breaks the protocol is answered with MessageError and the connection closed; a
request for an unknown key gets OBJECT_NOT_EXIST; nothing a client sends stops the server.
GIOP 1.0 and 1.1 requests are served too. Their body follows the header at once, so it may start
at an offset that is not a multiple of 8: `bodies.body_in` hands it to generated decoders with
padding that keeps its values' alignment.
"""

from __future__ import annotations

import contextlib
import ipaddress
import itertools
import os
import socket
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from miro_gen.corba import bodies, giop
from miro_gen.corba.connection import DEFAULT_MAX_MESSAGE
from miro_gen.corba.giop import GiopError, LocateStatus, MsgType, ReplyStatus
from miro_gen.corba.inbound import Budget, Message, Refused
from miro_gen.corba.ior import IOR, CorbaRef, iiop_endpoint, ref_from_ior
from miro_gen.corba.server_io import STALL, ConnectionLoop, ServerConnection
from miro_gen.exceptions import (
    BAD_OPERATION,
    NO_IMPLEMENT,
    OBJECT_NOT_EXIST,
    TRANSIENT,
    CompletionStatus,
)
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import BE, LE
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

DEFAULT_WORKERS = 16
DEFAULT_BUDGET = 160 << 20  # bytes of requests (reserved twice their size) and unsent replies
BUDGET_RESERVE = 16 << 20  # ... of which this much only for messages of at most 64 KiB
DEFAULT_MAX_CONNECTIONS = 256  # and never more than half the process's descriptor limit
MAX_WAITING = 10_000  # requests waiting for a worker
BACKLOG = 128
_OBJECT = "IDL:omg.org/CORBA/Object:1.0"
_OBJECT_OPERATIONS = {
    "_is_a", "_non_existent", "_not_existent", "_repository_id",
    "_interface", "_get_interface", "_component", "_get_component",
}  # fmt: skip


class BeyondLoopback(ValueError):
    """The address to listen on is not loopback, and serving beyond it was not allowed."""

    def __init__(self, address: str, port: int) -> None:
        super().__init__(f"IIOP on {address}:{port} would be served beyond this machine")
        self.address = address
        self.port = port


Locator = Callable[[bytes], "rpc.Servant | None"]
_current = threading.local()


def current_connection() -> ServerConnection | None:
    """The connection of the request this thread serves (None outside a request): what a
    servant that must know who calls (CosNaming: who owns a name) asks of its caller."""
    conn: ServerConnection | None = getattr(_current, "conn", None)
    return conn


def _listen(bind: str, port: int, beyond_loopback: bool) -> socket.socket:
    """A listening TCP socket bound to `bind`:`port`, checked to be loopback unless
    `beyond_loopback` (before it listens: nobody can connect to a refused one)."""
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if family == socket.AF_INET6:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
        sock.bind((bind, port))
        address = sock.getsockname()[0]
        if not beyond_loopback and not ipaddress.ip_address(address.partition("%")[0]).is_loopback:
            raise BeyondLoopback(address, sock.getsockname()[1])
        sock.listen(BACKLOG)
    except OSError as e:
        sock.close()
        raise TRANSIENT(f"cannot listen for IIOP on {bind}:{port}: {e.strerror or e}") from None
    except BaseException:
        sock.close()
        raise
    return sock


def _connection_cap(wanted: int) -> int:
    """`wanted`, but at most half the descriptors this process may open."""
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    except (ImportError, OSError, ValueError):
        return wanted
    if soft == resource.RLIM_INFINITY:
        return wanted
    return max(1, min(wanted, soft // 2))


class IIOPServer:
    """Serves servants over IIOP on `bind`:`port` (0: any free port), advertising `host` in
    the IORs it makes. `invoker`: the process's `IIOPInvoker`, through which servants' object
    arguments are called. `bind` must be a loopback address unless `beyond_loopback`.
    `budget`, `max_connections`, `stall`: the limits (`server_io`, `inbound`)."""

    def __init__(
        self,
        invoker: Any,
        bind: str = "127.0.0.1",
        port: int = 0,
        host: str | None = None,
        workers: int = DEFAULT_WORKERS,
        max_message: int = DEFAULT_MAX_MESSAGE,
        *,
        beyond_loopback: bool = False,
        budget: int = DEFAULT_BUDGET,
        max_connections: int = DEFAULT_MAX_CONNECTIONS,
        stall: float = STALL,
    ) -> None:
        self.invoker = invoker
        listener = _listen(bind, port, beyond_loopback)
        self.port = listener.getsockname()[1]
        self.host = host or (bind if bind not in ("0.0.0.0", "::", "") else socket.gethostname())
        self.endpoint = iiop_endpoint(self.host, self.port)
        self.max_message = max_message
        self._servants: dict[bytes, rpc.Servant] = {}
        self._keys: dict[int, bytes] = {}  # id(servant) -> key
        self._locators: list[tuple[bytes, Locator]] = []
        self._counter = itertools.count(1)
        self._prefix = f"miro.{os.getpid()}.".encode()
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="miro-iiop")
        self._waiting = 0  # requests handed to the pool and not yet done
        self.budget = Budget(budget, min(BUDGET_RESERVE, budget // 4))
        self._closed = False
        if getattr(invoker, "server", None) is None:
            invoker.server = self
        self.io = ConnectionLoop(
            listener,
            self._handle,
            self.budget,
            max_message,
            _connection_cap(max_connections),
            stall,
        )

    # ---- objects --------------------------------------------------------------------------------

    def activate(self, servant: rpc.Servant, key: bytes | str | None = None) -> CorbaRef:
        """Serve `servant` under `key` (by default a fresh one, for this run only)."""
        if isinstance(key, str):
            key = key.encode("utf-8")
        with self._lock:
            if key is None:
                key = (
                    self._keys.get(id(servant)) or self._prefix + str(next(self._counter)).encode()
                )
            self._servants[key] = servant
            self._keys[id(servant)] = key
        return self.reference(key, servant._repo_id)

    def deactivate(self, key: bytes | str) -> None:
        if isinstance(key, str):
            key = key.encode("utf-8")
        with self._lock:
            servant = self._servants.pop(key, None)
            if servant is not None and self._keys.get(id(servant)) == key:
                del self._keys[id(servant)]

    def deactivate_servant(self, servant: rpc.Servant) -> None:
        key = self._keys.get(id(servant))
        if key is not None:
            self.deactivate(key)

    def reference(self, key: bytes, repo_id: str) -> CorbaRef:
        ref = ref_from_ior(self.ior(key, repo_id))
        assert isinstance(ref, CorbaRef)
        return ref

    def ior(self, key: bytes, repo_id: str) -> IOR:
        return IOR.iiop(repo_id, self.host, self.port, key)

    def reference_for(self, servant: rpc.Servant) -> CorbaRef:
        key = self._keys.get(id(servant))
        if key is not None:
            return self.reference(key, servant._repo_id)
        return self.activate(servant)

    def add_locator(self, prefix: bytes, locator: Locator) -> None:
        """Serve every key that starts with `prefix` and names no activated servant by the
        servant `locator(key)` returns (None: no such object), as a POA's servant locator does:
        objects too many or too short-lived to activate one by one (naming contexts,
        iterators)."""
        with self._lock:
            self._locators.append((prefix, locator))

    def _servant(self, key: bytes) -> rpc.Servant | None:
        servant = self._servants.get(key)
        if servant is None and self._locators:
            for prefix, locator in self._locators:
                if key.startswith(prefix):
                    return locator(key)
        return servant

    # ---- messages (on the connection loop's thread) ---------------------------------------------

    def _handle(self, conn: ServerConnection, item: Message | Refused) -> bool:
        """One message of `conn`; False when the connection is to be closed."""
        if isinstance(item, Refused):
            self._refuse(conn, item)
            return True
        handed = False
        try:
            handed, keep = self._message(conn, item)
            return keep
        finally:
            if not handed:
                self.io.done(conn, item.charge)

    def _message(self, conn: ServerConnection, msg: Message) -> tuple[bool, bool]:
        """Handle one message: whether it went to a worker (which gives it back), and whether
        the connection stays open."""
        h, data = msg.header, msg.data
        if h.type == MsgType.REQUEST:
            return self._request(conn, h, giop.decode_request(data, h), msg), True
        if h.type == MsgType.LOCATE_REQUEST:
            request_id, key = giop.decode_locate_request(data, h)
            found = self._servant(key) is not None
            status = LocateStatus.OBJECT_HERE if found else LocateStatus.UNKNOWN_OBJECT
            self.io.send(conn, giop.encode_locate_reply(h.minor, request_id, status))
        elif h.type == MsgType.CANCEL_REQUEST:
            conn.cancelled.add(giop.decode_request_id(data, h))
            if len(conn.cancelled) > 10_000:
                conn.cancelled.clear()
        elif h.type in (MsgType.CLOSE_CONNECTION, MsgType.MESSAGE_ERROR):
            if h.type == MsgType.MESSAGE_ERROR:
                _peer_warnings.warning("IIOP: %s could not read a message of ours", conn.peer)
            return False, False
        else:
            raise GiopError(f"a client sent a {h.type.name} message")
        return False, True

    def _refuse(self, conn: ServerConnection, refused: Refused) -> None:
        """Answer a message the budget had no room for: TRANSIENT to a request (which may be
        sent again), the connection closed for anything else."""
        h = refused.header
        if h.type != MsgType.REQUEST:
            raise GiopError(f"a {h.size}-byte {h.type.name} message, and no room for it")
        request_id, expected = giop.request_id_of(refused.head, h)
        if expected:
            busy = TRANSIENT(
                f"{self.endpoint} has too much in hand for a {h.size}-byte request (its byte "
                f"budget is {self.budget.total >> 20} MiB): try again",
                completed=CompletionStatus.NO,
            )
            status, payload, contexts = bodies.reply_out(rpc.system_exception_reply(busy))
            self.io.send(conn, giop.encode_reply(h.minor, request_id, status, payload, contexts))

    # ---- requests -------------------------------------------------------------------------------

    def _request(
        self, conn: ServerConnection, h: giop.Header, req: giop.Request, msg: Message
    ) -> bool:
        """Serve a request: whether it went to a worker."""
        servant = self._servant(req.key)
        expected = req.response_expected
        if req.sync_flags == 1:  # SYNC_WITH_SERVER: acknowledge receipt, then run as one-way
            self.io.send(
                conn, giop.encode_reply(req.minor, req.request_id, ReplyStatus.NO_EXCEPTION, b"")
            )
            expected = False
        if servant is None:
            reply = rpc.system_exception_reply(
                OBJECT_NOT_EXIST(
                    f"no object with key {req.key!r} here", completed=CompletionStatus.NO
                )
            )
            if expected:
                self._send_reply(conn, req, reply)
            return False
        if req.operation in _OBJECT_OPERATIONS and req.operation not in servant._dispatch:
            reply = self._object_operation(servant, req, msg.data)
            if expected:
                self._send_reply(conn, req, reply)
            return False
        if isinstance(msg.data, bytearray):
            body = bodies.body_taken(msg.data, req.body, req.little)
        else:
            body = bodies.body_in(msg.data, req.body, req.little)
        if rpc.is_nonblocking(servant, req.operation):
            self._run(conn, req, servant, body, expected)
            return False
        with self._lock:
            full = self._waiting >= MAX_WAITING
            if not full:
                self._waiting += 1
        if full:
            if expected:
                busy = TRANSIENT(f"{self.endpoint} is overloaded", completed=CompletionStatus.NO)
                self._send_reply(conn, req, rpc.system_exception_reply(busy))
            return False
        try:
            self._pool.submit(self._work, conn, req, servant, body, expected, msg.charge)
        except RuntimeError:  # the pool is shut down: the server is closing
            with self._lock:
                self._waiting -= 1
            return False
        return True

    def _work(
        self,
        conn: ServerConnection,
        req: giop.Request,
        servant: rpc.Servant,
        body: bytes,
        expected: bool,
        charge: int,
    ) -> None:
        try:
            self._run(conn, req, servant, body, expected)
        finally:
            with self._lock:
                self._waiting -= 1
            self.io.done(conn, charge)

    def _run(
        self,
        conn: ServerConnection,
        req: giop.Request,
        servant: rpc.Servant,
        body: bytes,
        expected: bool,
    ) -> None:
        if req.request_id in conn.cancelled:
            conn.cancelled.discard(req.request_id)
            return
        _current.conn = conn
        try:
            reply = servant._invoke(req.operation, body, self.invoker)
        except BaseException as e:  # _invoke turns every exception into a reply; a last guard
            _log.exception("IIOP: %s failed", req.operation)
            reply = rpc.system_exception_reply(BAD_OPERATION(f"{req.operation}: {e!r}"))
        finally:
            _current.conn = None
        if expected and not conn.closed:
            self._send_reply(conn, req, reply)

    def _send_reply(self, conn: ServerConnection, req: giop.Request, reply: rpc.Reply) -> None:
        status, payload, contexts = bodies.reply_out(reply)
        self.io.send(conn, giop.encode_reply(req.minor, req.request_id, status, payload, contexts))

    def _object_operation(
        self, servant: rpc.Servant, req: giop.Request, msg: bytes | bytearray
    ) -> rpc.Reply:
        """CORBA::Object's own operations: _is_a, _non_existent, _repository_id."""
        out = CdrOutput()
        if req.operation == "_is_a":
            inp = CdrInput(msg, req.body, LE if req.little else BE)
            wanted = inp.string("repository id")
            ids = {getattr(c, "_repo_id", None) for c in type(servant).__mro__} | {_OBJECT}
            out.boolean(wanted in ids)
        elif req.operation in ("_non_existent", "_not_existent"):
            out.boolean(False)
        elif req.operation == "_repository_id":
            out.string(servant._repo_id)
        else:  # _interface, _get_interface, _component, _get_component
            return rpc.system_exception_reply(
                NO_IMPLEMENT(f"{req.operation} is not supported", completed=CompletionStatus.NO)
            )
        return rpc.Reply(rpc.ReplyStatus.OK, b"\x00\x01\x00\x00" + out.getvalue())

    # ---- the end --------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop serving: CloseConnection to every client (which may then retry elsewhere)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self.io.close()
        self._pool.shutdown(wait=False, cancel_futures=True)
