"""The client side of IIOP: an `Invoker` that generated stubs call CORBA objects through.

Each call takes a connection to the object's address that no other call is using (opening one
when none is idle), sends its Request, and reads the Reply on the calling thread: no thread
hand-off, as omniORB does by default (one call per connection). What comes back is turned into
the transport-neutral `Reply`: results, a user exception (realigned if need be), a system
exception (any of CORBA's, with its minor code and completion status); a LOCATION_FORWARD is
followed, and remembered for the reference until the place forwarded to fails. Failures are
CORBA's: TRANSIENT when the object cannot be reached (nothing was sent), COMM_FAILURE when the
connection is lost during the call, TIMEOUT (after sending CancelRequest). A connection that the
server closed in order (CloseConnection) before answering is retried on a new one, as GIOP
allows. A ZeroMQ peer where a GIOP one was expected is reported as such.

What stays the same between calls is prepared once: the parsed profile of each reference (a
`_Target`) and the bytes of each operation's request header; a call packs a request id, a size
and its body, and a plain reply is recognised without a general decode.
"""

from __future__ import annotations

import itertools
import select
import socket
import threading
import time
from struct import Struct
from struct import pack as struct_pack
from typing import Any

from miro_gen.corba import bodies, giop
from miro_gen.corba.connection import (
    DEFAULT_MAX_MESSAGE,
    GiopConnection,
    NotGiop,
    greets_with_zmtp,
)
from miro_gen.corba.giop import GiopError, MsgType, ReplyStatus
from miro_gen.corba.ior import IOR, OUR_CODE_SETS, GiopBody, ior_from_ref, parse_url, ref_from_ior
from miro_gen.exceptions import BAD_PARAM, COMM_FAILURE, TIMEOUT, TRANSIENT, CompletionStatus
from miro_gen.log import logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import EncodedRef, ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, encapsulated

_log = logger("MIRO")

CONNECT_TIMEOUT = 2.0  # seconds to open a connection
MAX_FORWARDS = 10  # LOCATION_FORWARDs followed for one call
MAX_IDLE = 8  # idle connections kept per address
IDLE_CHECK = 1.0  # seconds idle after which a connection is checked before it is used again
MAX_TARGETS = 4096  # references whose parsed profiles are kept
_CODE_SETS = encapsulated()
_CODE_SETS.ulong(OUR_CODE_SETS.char_native)
_CODE_SETS.ulong(OUR_CODE_SETS.wchar_native)
CODE_SETS_CONTEXT = [(giop.SC_CODE_SETS, _CODE_SETS.getvalue())]
_REPLY12 = (Struct("<III"), Struct(">III"))  # request id, status, context count
_OK_HEADER = (b"\x00\x00\x00\x00", b"\x00\x01\x00\x00")


def _plain_reply(request_id: int, little: bool) -> bytes:
    """Bytes 12 to 24 of a GIOP 1.2 reply to `request_id` with no exception and no contexts."""
    return _REPLY12[not little].pack(request_id, 0, 0)


class _Closed(Exception):
    """The server closed the connection in order before answering: the call can be retried."""


class ClientConnection(GiopConnection):
    """A connection that one call at a time uses."""

    def __init__(self, sock: socket.socket, address: tuple[str, int], max_message: int) -> None:
        super().__init__(sock, f"{address[0]}:{address[1]}", max_message)
        self.address = address
        self.sent_code_sets = False
        self.timeout: float | None = None
        self.last_used = time.monotonic()

    def usable(self) -> bool:
        """Whether an idle connection is still open (the server may have closed it meanwhile:
        then it is readable, at its end or with a CloseConnection)."""
        if time.monotonic() - self.last_used < IDLE_CHECK:
            return True
        try:
            readable, _, _ = select.select([self.sock], [], [], 0)
        except (OSError, ValueError):
            return False
        return not readable

    def set_timeout(self, timeout: float | None) -> None:
        """Make the socket's reads and writes give up after `timeout` seconds (None: never).
        The kernel times them (SO_RCVTIMEO, SO_SNDTIMEO) on a blocking socket: no extra system
        call per read, as Python's own socket timeouts make."""
        if timeout != self.timeout:
            t = 0.0 if timeout is None else max(timeout, 0.001)
            tv = struct_pack("ll", int(t), int((t - int(t)) * 1e6))
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)
            self.timeout = timeout

    def send(self, data: bytes) -> None:
        try:
            self.sock.sendall(data)  # one call at a time: no lock
        except BlockingIOError:
            raise TimeoutError("send timed out") from None


class _Target:
    """One IOR, parsed for calling: its IIOP profile, GIOP version, addresses and the request
    templates of the operations called on it; `forward` is where a LOCATION_FORWARD sent it."""

    __slots__ = ("addresses", "forward", "idle", "ior", "key", "minor", "templates")

    def __init__(self, ior: IOR) -> None:
        profile = ior.iiop_profile()
        if profile is None:
            raise TRANSIENT(f"the reference has no IIOP profile ({ior.describe()})")
        self.ior = ior
        self.minor = min(profile.version[1], 2)
        self.key = profile.key
        self.addresses = profile.addresses()
        self.templates: dict[tuple[str, bool, bool, bool], giop.RequestTemplate] = {}
        self.forward: _Target | None = None
        self.idle: list[ClientConnection] = []  # the invoker's idle connections to addresses[0]

    def request(
        self, operation: str, request_id: int, oneway: bool, body: memoryview, code_sets: bool
    ) -> bytes:
        spec = (operation, oneway, bool(body), code_sets)
        template = self.templates.get(spec)
        if template is None:
            contexts = CODE_SETS_CONTEXT if code_sets else None
            template = giop.RequestTemplate(
                self.minor, not oneway, self.key, operation, bool(body), contexts
            )
            self.templates[spec] = template
        return template.message(request_id, body)


class IIOPInvoker:
    """Calls objects over IIOP; references that are not CORBA ones go to `fallback` (the
    ZeroMQ invoker). Local servants passed as arguments are served by `server` (an
    `IIOPServer`), made on first need by `make_server()` (by default one on 127.0.0.1: `Server`
    and `Client` give one that follows their address rules)."""

    def __init__(
        self,
        fallback: rpc.Invoker | None = None,
        *,
        server: Any = None,
        make_server: Any = None,
        max_message: int = DEFAULT_MAX_MESSAGE,
    ) -> None:
        self.fallback = fallback
        self.server = server
        self._make_server = make_server or self._loopback_server
        self.max_message = max_message
        self._idle: dict[tuple[str, int], list[ClientConnection]] = {}
        self._targets: dict[ObjectRef, _Target] = {}
        self._lock = threading.Lock()
        self._ids = itertools.count(1)
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
    ) -> rpc.Reply | None:
        target = self._targets.get(ref)
        if target is None:
            if not ref.endpoint.startswith("iiop://") and not hasattr(ref, "ior"):
                if self.fallback is None:
                    raise TRANSIENT(f"{ref.endpoint or 'a nil reference'} is not a CORBA object")
                return self.fallback.invoke(ref, operation, body, oneway=oneway, timeout=timeout)
            target = self._target(ref)
        payload = memoryview(body)[4:]
        deadline = time.monotonic() + timeout if timeout else None
        for _ in range(MAX_FORWARDS):
            here = target.forward or target
            try:
                reply = self._call(here, operation, payload, oneway, timeout, deadline)
            except (TRANSIENT, COMM_FAILURE) as e:
                if here is target or e.completed != CompletionStatus.NO:
                    raise
                target.forward = None  # where we were forwarded to is gone: back to the origin
                continue
            if reply is None or isinstance(reply, rpc.Reply):
                return reply
            target.forward = self._prepare(_Target(reply))
        raise TRANSIENT(f"{operation}: more than {MAX_FORWARDS} location forwards")

    def _target(self, ref: ObjectRef) -> _Target:
        target = self._prepare(_Target(ior_from_ref(ref)))
        with self._lock:
            if len(self._targets) >= MAX_TARGETS:
                self._targets.clear()
            self._targets[ref] = target
        return target

    def _loopback_server(self) -> Any:
        from miro_gen.corba.server import IIOPServer

        return IIOPServer(self)

    def reference_for(self, servant: rpc.Servant) -> ObjectRef:
        server = self.server
        if server is None and self._make_server is not None:
            with self._lock:
                if self.server is None:
                    self.server = self._make_server()
            server = self.server
        if server is None:
            if self.fallback is not None:
                return self.fallback.reference_for(servant)
            raise TRANSIENT("a local object can only be passed by a process that serves objects")
        ref: ObjectRef = server.reference_for(servant)
        return ref

    def encode_reference(self, value: Any) -> EncodedRef:
        """An object-reference argument as the IOR it travels as."""
        if isinstance(value, rpc.Servant):
            value = self.reference_for(value)
        elif value is not None and not isinstance(value, ObjectRef):
            value = getattr(value, "_ref", value)
            if not isinstance(value, ObjectRef):
                raise BAD_PARAM("expected an object reference, a stub or a servant")
        return EncodedRef(ior_from_ref(value or ObjectRef()).encode())

    # ---- one request ----------------------------------------------------------------------------

    def _call(
        self,
        target: _Target,
        operation: str,
        payload: memoryview,
        oneway: bool,
        timeout: float | None,
        deadline: float | None,
    ) -> rpc.Reply | IOR | None:
        for attempt in range(3):
            conn, fresh = self._connection(target, deadline)
            request_id = next(self._ids) & 0xFFFFFFFF
            code_sets = target.minor >= 1 and not conn.sent_code_sets
            msg = target.request(operation, request_id, oneway, payload, code_sets)
            try:
                conn.set_timeout(timeout)
                conn.send(msg)
            except OSError as e:
                conn.close()
                if fresh or attempt:
                    raise COMM_FAILURE(
                        f"{operation}: cannot send to {conn.peer}: {e}",
                        completed=CompletionStatus.NO,
                    ) from None
                continue  # a stale idle connection: try a fresh one
            conn.sent_code_sets = True
            if oneway:
                self._release(conn)
                return None
            try:
                result = self._await(conn, request_id, operation, deadline, fresh)
            except _Closed:
                conn.close()
                continue
            self._release(conn)
            return result
        raise TRANSIENT(f"{operation}: {target.addresses[0]} keeps closing connections")

    def _await(
        self,
        conn: ClientConnection,
        request_id: int,
        operation: str,
        deadline: float | None,
        fresh: bool,
    ) -> rpc.Reply | IOR:
        """The reply to `request_id`. A connection used before that fails at once is tried
        again on a new one (`_Closed`), as omniORB does: its server may have restarted."""
        while True:
            try:
                h, msg = conn.read_message()
            except (TimeoutError, BlockingIOError):
                conn.send_quietly(giop.encode_cancel(1, request_id))
                conn.close()
                raise TIMEOUT(
                    f"{operation}: no reply from {conn.peer} in time",
                    completed=CompletionStatus.MAYBE,
                ) from None
            except NotGiop as e:
                conn.close()
                raise not_giop(e, conn.peer) from None
            except GiopError as e:
                conn.send_quietly(giop.encode_simple(1, MsgType.MESSAGE_ERROR))
                conn.close()
                raise COMM_FAILURE(
                    f"{operation}: {conn.peer} broke the GIOP protocol: {e}",
                    completed=CompletionStatus.MAYBE,
                ) from None
            except (EOFError, OSError) as e:
                conn.close()
                if not fresh:
                    raise _Closed() from None
                if greets_with_zmtp(conn.peer):
                    raise not_giop(NotGiop("ZMTP greeting", zmq=True), conn.peer) from None
                raise COMM_FAILURE(
                    f"{operation}: lost the connection to {conn.peer}: {e}",
                    completed=CompletionStatus.MAYBE,
                ) from None
            if h.type == MsgType.REPLY:
                # The common case: GIOP 1.2, ours, no exception, no service contexts.
                if h.minor == 2 and msg[12:24] == _plain_reply(request_id, h.little):
                    return rpc.Reply(rpc.ReplyStatus.OK, GiopBody(_OK_HEADER[h.little] + msg[24:]))
                result = self._reply(conn, h, msg, request_id, operation)
                if result is not None:
                    return result
            elif h.type == MsgType.CLOSE_CONNECTION:
                raise _Closed()
            elif h.type == MsgType.MESSAGE_ERROR:
                conn.close()
                raise COMM_FAILURE(
                    f"{operation}: {conn.peer} could not read our GIOP 1.{h.minor} message",
                    completed=CompletionStatus.NO,
                )
            if deadline is not None:  # something else came: wait only for what is left
                left = deadline - time.monotonic()
                if left <= 0:
                    conn.close()
                    raise TIMEOUT(f"{operation}: no reply from {conn.peer} in time")
                conn.set_timeout(left)

    def _reply(
        self,
        conn: ClientConnection,
        h: giop.Header,
        msg: bytes,
        request_id: int,
        operation: str,
    ) -> rpc.Reply | IOR | None:
        try:
            reply = giop.decode_reply(msg, h)
            if reply.request_id != request_id:
                return None  # a late reply to a call that gave up
            return _result(reply, msg, operation, conn.peer)
        except GiopError as e:
            conn.close()
            raise COMM_FAILURE(
                f"{operation}: {conn.peer}: {e}", completed=CompletionStatus.MAYBE
            ) from None
        except COMM_FAILURE:
            raise
        except Exception as e:  # a malformed body: this call's failure, not the process's
            raise COMM_FAILURE(
                f"{operation}: malformed reply from {conn.peer}: {e}",
                completed=CompletionStatus.MAYBE,
            ) from None

    # ---- connections ----------------------------------------------------------------------------

    def _prepare(self, target: _Target) -> _Target:
        with self._lock:
            target.idle = self._idle.setdefault(target.addresses[0], [])
        return target

    def _connection(self, target: _Target, deadline: float | None) -> tuple[ClientConnection, bool]:
        """An idle connection to the object's address (not fresh), or a new one (fresh).
        The idle lists are used without a lock: list.pop and append are atomic."""
        if self._closed:
            raise TRANSIENT("the IIOP invoker is closed")
        idle = target.idle
        while idle:
            try:
                conn = idle.pop()
            except IndexError:
                break
            if conn.usable():
                return conn, False
            conn.close()
        errors = []
        for host, port in target.addresses:
            wait = CONNECT_TIMEOUT
            if deadline is not None:
                wait = max(0.01, min(wait, deadline - time.monotonic()))
            try:
                sock = socket.create_connection((host, port), timeout=wait)
            except OSError as e:
                errors.append(f"{host}:{port}: {e.strerror or e}")
                continue
            sock.settimeout(None)
            return ClientConnection(sock, target.addresses[0], self.max_message), True
        raise TRANSIENT(f"cannot reach {'; '.join(errors)}", completed=CompletionStatus.NO)

    def _release(self, conn: ClientConnection) -> None:
        conn.last_used = time.monotonic()
        idle = self._idle.get(conn.address)
        if idle is not None and len(idle) < MAX_IDLE and not self._closed and not conn.closed:
            idle.append(conn)
        else:
            conn.close()

    # ---- lookups --------------------------------------------------------------------------------

    def locate(self, ref: ObjectRef, timeout: float = 5.0) -> giop.LocateStatus:
        """Ask the server whether it has the object (a LocateRequest)."""
        target = self._prepare(_Target(ior_from_ref(ref)))
        conn, _ = self._connection(target, time.monotonic() + timeout)
        request_id = next(self._ids) & 0xFFFFFFFF
        try:
            conn.set_timeout(timeout)
            conn.send(giop.encode_locate_request(target.minor, request_id, target.key))
            while True:
                h, msg = conn.read_message()
                if h.type == MsgType.LOCATE_REPLY:
                    rid, status, _ = giop.decode_locate_reply(msg, h)
                    if rid == request_id:
                        self._release(conn)
                        return status
                elif h.type in (MsgType.CLOSE_CONNECTION, MsgType.MESSAGE_ERROR):
                    raise EOFError(f"{conn.peer} closed the connection")
        except NotGiop as e:
            conn.close()
            raise not_giop(e, conn.peer) from None
        except (OSError, EOFError, GiopError) as e:
            conn.close()
            raise TRANSIENT(f"cannot locate the object at {conn.peer}: {e}") from None

    def stub(self, cls: type[rpc.StubT], ior: IOR | str) -> rpc.StubT:
        """A stub of `cls` for an IOR, or for any reference string `parse_url` reads."""
        if isinstance(ior, str):
            parsed = parse_url(ior, cls._repo_id)
            if not isinstance(parsed, IOR):
                raise BAD_PARAM("a corbaname URL names an object in a naming service: resolve it")
            ior = parsed
        return cls(ref_from_ior(ior), self)

    def close(self) -> None:
        self._closed = True
        with self._lock:
            conns = [c for idle in self._idle.values() for c in idle]
            self._idle.clear()
        for conn in conns:
            conn.close()
        if self.server is not None:
            self.server.close()


def _result(reply: giop.Reply, msg: bytes, operation: str, peer: str) -> rpc.Reply | IOR:
    s = reply.status
    if s == ReplyStatus.NO_EXCEPTION:
        return rpc.Reply(rpc.ReplyStatus.OK, bodies.body_in(msg, reply.body, reply.little))
    if s == ReplyStatus.USER_EXCEPTION:
        return bodies.user_exception_in(msg, reply.body, reply.little)
    if s == ReplyStatus.SYSTEM_EXCEPTION:
        return bodies.system_exception_in(msg, reply.body, reply.little, reply.contexts, peer)
    if s in (ReplyStatus.LOCATION_FORWARD, ReplyStatus.LOCATION_FORWARD_PERM):
        target = IOR.read(CdrInput(msg, reply.body, 0 if reply.little else 1))
        _log.debug("%s: forwarded to %s", operation, target.describe())
        return target
    raise COMM_FAILURE(
        f"{operation}: {peer} asks for an addressing mode other than the object key",
        completed=CompletionStatus.NO,
    )


def not_giop(e: NotGiop, peer: str) -> TRANSIENT:
    if e.zmq:
        return TRANSIENT(
            f"{peer} is a ZeroMQ peer (a miro naming service or a miro-gen server), not a "
            f"CORBA one: reach it with --naming tcp://{peer}",
            completed=CompletionStatus.NO,
        )
    return TRANSIENT(f"{peer} does not speak GIOP: {e}", completed=CompletionStatus.NO)
