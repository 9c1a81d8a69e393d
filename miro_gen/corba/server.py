"""The server side of IIOP: servants of generated skeletons, served to CORBA clients.

One listening socket per process; a thread per connection reads its messages. A request runs on
the connection's thread when its method is marked `@nonblocking`, else on a bounded worker pool
(so that one connection may carry several calls at once, as TAO multiplexes them), and the reply
is sent when it is ready. Object keys are what the caller names them (`add_to_name_service`
uses the full name, `robot1/ExampleA`): with a fixed port, a restarted server publishes the very
same IORs, as a persistent POA does, and `corbaloc:iiop:HOST:PORT/robot1/ExampleA` reaches it.

A message that breaks the protocol is answered with MessageError and the connection closed; a
request for an unknown key gets OBJECT_NOT_EXIST; nothing a client sends stops the server.
GIOP 1.0 and 1.1 requests are served too. Their body follows the header at once, so it may start
at an offset that is not a multiple of 8: `bodies.body_in` hands it to generated decoders with
padding that keeps its values' alignment.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import socket
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from miro_gen.corba import bodies, giop
from miro_gen.corba.connection import DEFAULT_MAX_MESSAGE, GiopConnection, NotGiop
from miro_gen.corba.giop import GiopError, LocateStatus, MsgType, ReplyStatus
from miro_gen.corba.ior import IOR, CorbaRef, iiop_endpoint, ref_from_ior
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
_OBJECT = "IDL:omg.org/CORBA/Object:1.0"


class _ServerConnection(GiopConnection):
    def __init__(self, sock: socket.socket, peer: str, max_message: int) -> None:
        super().__init__(sock, peer, max_message)
        self.cancelled: set[int] = set()


class IIOPServer:
    """Serves servants over IIOP on `bind`:`port` (0: any free port), advertising `host` in
    the IORs it makes. `invoker`: the process's `IIOPInvoker`, through which servants' object
    arguments are called."""

    def __init__(
        self,
        invoker: Any,
        bind: str = "127.0.0.1",
        port: int = 0,
        host: str | None = None,
        workers: int = DEFAULT_WORKERS,
        max_message: int = DEFAULT_MAX_MESSAGE,
    ) -> None:
        self.invoker = invoker
        family = socket.AF_INET6 if ":" in bind else socket.AF_INET
        try:
            self._listener = socket.create_server((bind, port), family=family, backlog=64)
        except OSError as e:
            raise TRANSIENT(f"cannot listen for IIOP on {bind}:{port}: {e.strerror or e}") from None
        self.port = self._listener.getsockname()[1]
        self.host = host or (bind if bind not in ("0.0.0.0", "::", "") else socket.gethostname())
        self.endpoint = iiop_endpoint(self.host, self.port)
        self.max_message = max_message
        self._servants: dict[bytes, rpc.Servant] = {}
        self._keys: dict[int, bytes] = {}  # id(servant) -> key
        self._counter = itertools.count(1)
        self._prefix = f"miro.{os.getpid()}.".encode()
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="miro-iiop")
        self._connections: set[_ServerConnection] = set()
        self._closed = False
        if getattr(invoker, "server", None) is None:
            invoker.server = self
        threading.Thread(target=self._accept, name="miro-iiop-accept", daemon=True).start()

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

    def _servant(self, key: bytes) -> rpc.Servant | None:
        return self._servants.get(key)

    # ---- connections ----------------------------------------------------------------------------

    def _accept(self) -> None:
        while not self._closed:
            try:
                sock, addr = self._listener.accept()
            except OSError:
                if self._closed:
                    return
                continue
            conn = _ServerConnection(sock, f"{addr[0]}:{addr[1]}", self.max_message)
            with self._lock:
                if self._closed:
                    conn.close()
                    return
                self._connections.add(conn)
            threading.Thread(
                target=self._serve, args=(conn,), name="miro-iiop-conn", daemon=True
            ).start()

    def _serve(self, conn: _ServerConnection) -> None:
        try:
            while not self._closed:
                try:
                    h, msg = conn.read_message()
                except NotGiop as e:
                    _peer_warnings.warning("IIOP: %s; closing the connection", e)
                    if not e.zmq:  # a ZeroMQ peer would not understand it
                        conn.send_quietly(giop.encode_simple(1, MsgType.MESSAGE_ERROR))
                    return
                except GiopError as e:
                    _peer_warnings.warning("IIOP: %s: %s; answered with MessageError", conn.peer, e)
                    conn.send_quietly(giop.encode_simple(1, MsgType.MESSAGE_ERROR))
                    return
                except (EOFError, OSError):
                    return
                try:
                    if not self._message(conn, h, msg):
                        return
                except GiopError as e:
                    _peer_warnings.warning("IIOP: %s: %s; answered with MessageError", conn.peer, e)
                    conn.send_quietly(giop.encode_simple(h.minor, MsgType.MESSAGE_ERROR))
                    return
                except OSError:
                    return
                except Exception:  # a defect of ours: logged, and this connection only ends
                    _log.exception("IIOP: cannot handle a %s from %s", h.type.name, conn.peer)
                    conn.send_quietly(giop.encode_simple(h.minor, MsgType.MESSAGE_ERROR))
                    return
        finally:
            with self._lock:
                self._connections.discard(conn)
            conn.close()

    def _message(self, conn: _ServerConnection, h: giop.Header, msg: bytes) -> bool:
        """Handle one message; False when the connection is to be closed."""
        if h.type == MsgType.REQUEST:
            self._request(conn, h, giop.decode_request(msg, h), msg)
        elif h.type == MsgType.LOCATE_REQUEST:
            request_id, key = giop.decode_locate_request(msg, h)
            found = self._servant(key) is not None
            status = LocateStatus.OBJECT_HERE if found else LocateStatus.UNKNOWN_OBJECT
            conn.send(giop.encode_locate_reply(h.minor, request_id, status))
        elif h.type == MsgType.CANCEL_REQUEST:
            conn.cancelled.add(giop.decode_request_id(msg, h))
            if len(conn.cancelled) > 10_000:
                conn.cancelled.clear()
        elif h.type in (MsgType.CLOSE_CONNECTION, MsgType.MESSAGE_ERROR):
            if h.type == MsgType.MESSAGE_ERROR:
                _peer_warnings.warning("IIOP: %s could not read a message of ours", conn.peer)
            return False
        else:
            raise GiopError(f"a client sent a {h.type.name} message")
        return True

    # ---- requests -------------------------------------------------------------------------------

    def _request(
        self, conn: _ServerConnection, h: giop.Header, req: giop.Request, msg: bytes
    ) -> None:
        servant = self._servant(req.key)
        expected = req.response_expected
        if req.sync_flags == 1:  # SYNC_WITH_SERVER: acknowledge receipt, then run as one-way
            conn.send(giop.encode_reply(req.minor, req.request_id, ReplyStatus.NO_EXCEPTION, b""))
            expected = False
        if servant is None:
            reply = rpc.system_exception_reply(
                OBJECT_NOT_EXIST(
                    f"no object with key {req.key!r} here", completed=CompletionStatus.NO
                )
            )
            if expected:
                self._send_reply(conn, req, reply)
            return
        body = bodies.body_in(msg, req.body, req.little)
        if req.operation.startswith("_") and req.operation not in servant._dispatch:
            reply = self._object_operation(servant, req, msg)
            if expected:
                self._send_reply(conn, req, reply)
            return
        if rpc.is_nonblocking(servant, req.operation):
            self._run(conn, req, servant, body, expected)
        else:
            self._pool.submit(self._run, conn, req, servant, body, expected)

    def _run(
        self,
        conn: _ServerConnection,
        req: giop.Request,
        servant: rpc.Servant,
        body: bytes,
        expected: bool,
    ) -> None:
        if req.request_id in conn.cancelled:
            conn.cancelled.discard(req.request_id)
            return
        try:
            reply = servant._invoke(req.operation, body, self.invoker)
        except BaseException as e:  # _invoke turns every exception into a reply; a last guard
            _log.exception("IIOP: %s failed", req.operation)
            reply = rpc.system_exception_reply(BAD_OPERATION(f"{req.operation}: {e!r}"))
        if expected and not conn.closed:
            with contextlib.suppress(OSError):  # the client went away: nothing to tell it
                self._send_reply(conn, req, reply)

    def _send_reply(self, conn: _ServerConnection, req: giop.Request, reply: rpc.Reply) -> None:
        status, payload, contexts = bodies.reply_out(reply)
        conn.send(giop.encode_reply(req.minor, req.request_id, status, payload, contexts))

    def _object_operation(self, servant: rpc.Servant, req: giop.Request, msg: bytes) -> rpc.Reply:
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
        elif req.operation in ("_interface", "_get_interface", "_component", "_get_component"):
            return rpc.system_exception_reply(
                NO_IMPLEMENT(f"{req.operation} is not supported", completed=CompletionStatus.NO)
            )
        else:
            return servant._invoke(
                req.operation, bodies.body_in(msg, req.body, req.little), self.invoker
            )
        return rpc.Reply(rpc.ReplyStatus.OK, b"\x00\x01\x00\x00" + out.getvalue())

    # ---- the end --------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop serving: CloseConnection to every client (which may then retry elsewhere)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            conns = list(self._connections)
        with contextlib.suppress(OSError):  # wakes the thread blocked in accept()
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        for conn in conns:
            conn.send_quietly(giop.encode_simple(2, MsgType.CLOSE_CONNECTION))
            conn.close()
        self._pool.shutdown(wait=False, cancel_futures=True)
