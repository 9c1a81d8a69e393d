"""Stubs, skeletons and the transport-neutral invoker they call through.

A generated stub (client proxy) marshals its `in`/`inout` arguments into a CDR body and calls
`Invoker.invoke(ref, operation, body)`; a transport (ZeroMQ, or `LocalInvoker` in-process)
delivers the body to the servant's skeleton, whose dispatch table unmarshals the arguments,
calls the implementation and marshals the results. Replies say `OK`, `USER_EXCEPTION` (an IDL
exception, identified by its repository id) or `SYSTEM_EXCEPTION` (a CORBA-style failure).
"""

from __future__ import annotations

import enum
import itertools
import queue
import threading
from abc import ABC
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple, Protocol, TypeVar

from miro_gen.exceptions import (
    BAD_OPERATION,
    MARSHAL,
    NO_IMPLEMENT,
    OBJECT_NOT_EXIST,
    SYSTEM_EXCEPTIONS,
    TRANSIENT,
    UNKNOWN,
    CompletionStatus,
    SystemException,
    UserException,
)
from miro_gen.runtime.cdr import (
    HEADER_LE,
    Encoder,
    ObjectRef,
    get_string,
    header_endianness,
    pair,
    put_string,
)

StubT = TypeVar("StubT", bound="Stub")

DEFAULT_TIMEOUT = 10.0  # seconds a call waits for its reply unless the stub says otherwise


class ReplyStatus(enum.IntEnum):
    OK = 0
    USER_EXCEPTION = 1
    SYSTEM_EXCEPTION = 2


_OK = ReplyStatus.OK


_decoding = threading.local()  # `now`: a stub's call, whose reply is decoded at once


def decoded_at_once() -> bool:
    """Whether the reply of the call this thread is invoking is decoded by a generated stub
    before the thread invokes anything again: a transport may then give its body as a view
    of memory that it reuses at the thread's next call (`transport.rpc.shared`)."""
    return bool(getattr(_decoding, "now", False))


class Reply(NamedTuple):
    """What a call returns: a status, a CDR body, and for exceptions their repository id. A
    transport may give a large body as a read-only view over the frame it received (decoding
    then copies its octets once, not twice)."""

    status: ReplyStatus
    body: bytes | memoryview
    repo_id: str = ""


class Invoker(Protocol):
    """Delivers requests to the object a reference names; transports implement it."""

    def invoke(
        self,
        ref: ObjectRef,
        operation: str,
        body: bytes,
        *,
        oneway: bool = False,
        timeout: float | None = None,
    ) -> Reply | None:
        """Send a request; the reply (None for oneway calls)."""
        ...

    def reference_for(self, servant: Servant) -> ObjectRef:
        """A reference to a local servant, so it can be passed as an argument."""
        ...


# ---- system exceptions on the wire -------------------------------------------------------------

_SYSTEM_BODY = pair("II")


def system_exception_reply(exc: SystemException) -> Reply:
    """The reply that carries a system exception. Never fails: a message that is not text, or
    a minor code that is not a 32-bit number, is sent as best it can be."""
    message = exc.message
    if not isinstance(message, str):
        message = repr(message)
    message = message.replace("\0", "\\0").encode("utf-8", "replace").decode("utf-8")
    minor = exc.minor if isinstance(exc.minor, int) else 0
    completed = exc.completed if isinstance(exc.completed, int) else CompletionStatus.MAYBE
    buf = bytearray(HEADER_LE)
    buf += _SYSTEM_BODY[0].pack(minor & 0xFFFFFFFF, int(completed) & 0xFFFFFFFF)
    put_string(buf, message, None, "system exception message")
    repo_id = exc._repo_id if isinstance(exc._repo_id, str) else UNKNOWN._repo_id
    return Reply(ReplyStatus.SYSTEM_EXCEPTION, bytes(buf), repo_id)


def system_exception_parts(reply: Reply) -> tuple[int, CompletionStatus, str] | None:
    """The minor code, completion status and message a system exception reply carries; None
    when its body is malformed."""
    try:
        e = header_endianness(reply.body)
        minor, completed = _SYSTEM_BODY[e].unpack_from(reply.body, 4)
        message, _ = get_string(reply.body, 12, e, None, "system exception message")
        return minor, CompletionStatus(completed), message
    except Exception:
        return None


def raise_system_exception(reply: Reply) -> None:
    cls = SYSTEM_EXCEPTIONS.get(reply.repo_id, UNKNOWN)
    parts = system_exception_parts(reply)
    if parts is None:  # a malformed system exception is still a failure of the call
        parts = 0, CompletionStatus.MAYBE, f"{reply.repo_id} (malformed)"
    minor, status, message = parts
    raise cls(message, minor, status)


def raise_user_exception(reply: Reply, declared: tuple[type[UserException], ...]) -> None:
    for cls in declared:
        if cls._repo_id == reply.repo_id:
            raise cls.deserialize(reply.body)  # type: ignore[attr-defined]
    raise UNKNOWN(
        f"the server raised {reply.repo_id}, which this operation does not declare",
        completed=CompletionStatus.YES,
    )


# ---- stubs --------------------------------------------------------------------------------------


Rebind = Callable[[], ObjectRef]  # looks the object up again (in the naming service)


class Stub:
    """Base of generated client proxies: holds the object reference and the invoker, and for a
    stub found by name, how to look that name up again (`_set_rebind`)."""

    __slots__ = ("_invoker", "_rebind", "_ref", "_timeout")

    _repo_id: ClassVar[str] = "IDL:omg.org/CORBA/Object:1.0"
    _interface_hash: ClassVar[str] = ""  # SHA-256 of the interface schema (see Servant)

    def __init__(self, ref: ObjectRef, invoker: Invoker, timeout: float | None = None) -> None:
        self._ref = ref
        self._invoker = invoker
        self._timeout = DEFAULT_TIMEOUT if timeout is None else timeout
        self._rebind: Rebind | None = None

    def _set_rebind(self, rebind: Rebind | None) -> None:
        """Follow the object when its server moves (`rebind` looks it up again), or not (None).

        A call that fails before its request was delivered (TRANSIENT or OBJECT_NOT_EXIST,
        completed NO: the server's old endpoint is gone, or it restarted and the object's key
        is new) looks the object up again and, if it is elsewhere now, is sent once more.
        Never after delivery (COMM_FAILURE, TIMEOUT): at most once stays at most once.
        `Client.resolve_name` sets this for the stubs it returns."""
        self._rebind = rebind

    def _call(
        self, operation: str, body: bytes, declared: tuple[type[UserException], ...] = ()
    ) -> bytes | memoryview:
        """Invoke and return the reply body; raise what the server raised. The generated stub
        decodes the body before its thread invokes anything again (`decoded_at_once`)."""
        _decoding.now = True
        try:
            reply = self._invoker.invoke(self._ref, operation, body, timeout=self._timeout)
        except (TRANSIENT, OBJECT_NOT_EXIST) as exc:
            reply = self._again(exc, operation, body)
        finally:
            _decoding.now = False
        if reply is None:
            raise MARSHAL(f"no reply to {operation}", completed=CompletionStatus.MAYBE)
        if reply.status is _OK:
            return reply.body
        if reply.status == ReplyStatus.SYSTEM_EXCEPTION and self._undelivered(reply):
            _decoding.now = True
            try:
                reply = self._invoker.invoke(self._ref, operation, body, timeout=self._timeout)
            finally:
                _decoding.now = False
            if reply is None:  # pragma: no cover - only oneway calls have no reply
                raise MARSHAL(f"no reply to {operation}", completed=CompletionStatus.MAYBE)
            if reply.status is _OK:
                return reply.body
        if reply.status == ReplyStatus.USER_EXCEPTION:
            raise_user_exception(reply, declared)
        raise_system_exception(reply)
        raise AssertionError("unreachable")  # pragma: no cover

    def _send(self, operation: str, body: bytes) -> None:
        """Invoke a oneway operation: no reply is awaited."""
        try:
            self._invoker.invoke(self._ref, operation, body, oneway=True, timeout=self._timeout)
        except (TRANSIENT, OBJECT_NOT_EXIST) as exc:
            self._again(exc, operation, body, oneway=True)

    def _again(
        self, exc: SystemException, operation: str, body: bytes, oneway: bool = False
    ) -> Reply | None:
        """After `exc` (raised by the invoker): once more at the object's new address if it
        was not delivered and the object has moved; else `exc` stands."""
        if self._rebind is None or exc.completed != CompletionStatus.NO or not self._moved():
            raise exc
        return self._invoker.invoke(
            self._ref, operation, body, oneway=oneway, timeout=self._timeout
        )

    def _undelivered(self, reply: Reply) -> bool:
        """Whether a system exception reply says the request ran nowhere (OBJECT_NOT_EXIST or
        TRANSIENT, completed NO) and, for a stub that follows its name, the object moved."""
        return (
            self._rebind is not None
            and reply.repo_id in _UNDELIVERED
            and _not_completed(reply)
            and self._moved()
        )

    def _moved(self) -> bool:
        """Look the object up again; whether its reference changed (then it is used)."""
        assert self._rebind is not None
        try:
            ref = self._rebind()
        except Exception:  # not bound (yet), naming unreachable: the first failure stands
            return False
        if ref == self._ref:
            return False
        self._ref = ref
        return True

    def _narrow(self, cls: type[StubT]) -> StubT:
        """This reference as a stub of `cls` (e.g. an `Object` received, as the interface it
        is known to be). Not checked here: a wrong guess fails with BAD_OPERATION on use."""
        stub = cls(self._ref, self._invoker, self._timeout)
        stub._rebind = self._rebind
        return stub

    def __repr__(self) -> str:
        return f"<{type(self).__name__} stub for {self._ref.endpoint or '?'} key={self._ref.key!r}>"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Stub) and other._ref == self._ref

    def __hash__(self) -> int:
        return hash(self._ref)


_UNDELIVERED = frozenset((TRANSIENT._repo_id, OBJECT_NOT_EXIST._repo_id))


def _not_completed(reply: Reply) -> bool:
    """Whether a system exception reply says the operation did not run (completed NO)."""
    try:
        e = header_endianness(reply.body)
        return bool(_SYSTEM_BODY[e].unpack_from(reply.body, 4)[1] == CompletionStatus.NO)
    except Exception:
        return False


def make_stub(cls: type[Any], ref: ObjectRef, invoker: Invoker) -> Any:
    """A stub of `cls` for a reference received in a reply or a request (None for nil)."""
    return cls(ref, invoker) if ref else None


def to_ref(value: Any, invoker: Invoker) -> Any:
    """What an object-reference argument travels as: stubs and references as they are, a local
    servant as a reference the invoker makes for it; for an invoker that encodes references
    its own way (IIOP: as IORs), what its `encode_reference(value)` makes of the value."""
    encode = getattr(invoker, "encode_reference", None)
    if encode is not None:
        return encode(value)
    if isinstance(value, Servant):
        return invoker.reference_for(value)
    return value


# ---- skeletons ---------------------------------------------------------------------------------

# A skeleton's function for one operation: the request body in, the reply body out, as the
# encoder it was written to (its large payloads set aside, not yet joined: `Encoder.value()`),
# or as bytes (hand-written tables).
Dispatcher = Callable[[Any, bytes, "Invoker"], "bytes | Encoder"]


F = TypeVar("F", bound=Callable[..., Any])


def nonblocking(method: F) -> F:
    """Mark a servant method that returns at once: it never waits for data, never sleeps and
    never calls another object. A server runs such methods on the thread that receives the
    request and never hands the socket to another thread meanwhile (which it does for other
    methods that take long). A marked method that blocks stops its process from serving calls
    meanwhile: mark only what is quick."""
    method._miro_nonblocking = True  # type: ignore[attr-defined]
    return method


def is_nonblocking(servant: Servant, operation: str) -> bool:
    """Whether `servant` implements `operation` with a method marked @nonblocking."""
    method = getattr(type(servant), operation, None)
    return bool(getattr(method, "_miro_nonblocking", False))


class Servant(ABC):  # noqa: B024 - generated subclasses declare the abstract methods
    """Base of generated skeletons. `_dispatch` maps operation names to functions that
    unmarshal the request, call the implementation and marshal the results."""

    _repo_id: ClassVar[str] = "IDL:omg.org/CORBA/Object:1.0"
    _dispatch: ClassVar[dict[str, Dispatcher]] = {}
    # The interface's self-contained IDL (docs/CODEGEN.md), which the process's service object
    # gives callers without generated code, and its SHA-256; empty for hand-written servants.
    _interface_schema: ClassVar[str] = ""
    _interface_hash: ClassVar[str] = ""

    def _invoke(self, operation: str, body: bytes, invoker: Invoker) -> Reply:
        """Run one request: a reply, whatever the implementation did or raised."""
        result = self._result(operation, body, invoker)
        if isinstance(result, Reply):
            return result
        return Reply(ReplyStatus.OK, result.value() if isinstance(result, Encoder) else result)

    def _result(self, operation: str, body: bytes, invoker: Invoker) -> Reply | Encoder | bytes:
        """Run one request: an ok result as the skeleton gave it (its encoder, whose parts a
        transport may copy straight into shared memory, never joined into one body), or a
        reply: an exception, whatever the implementation did or raised."""
        handler = self._dispatch.get(operation)
        if handler is None:
            return system_exception_reply(
                BAD_OPERATION(f"{self._repo_id} has no operation '{operation}'")
            )
        try:
            return handler(self, body, invoker)
        except UserException as exc:
            return _user_exception_reply(operation, exc)
        except SystemException as exc:
            return system_exception_reply(exc)
        except NotImplementedError as exc:
            return system_exception_reply(
                NO_IMPLEMENT(f"{operation}: {exc}", completed=CompletionStatus.NO)
            )
        except Exception as exc:  # the servant's bug: the client gets UNKNOWN, not a hang
            return system_exception_reply(_unknown(operation, exc))


def _unknown(operation: str, exc: BaseException) -> UNKNOWN:
    try:
        text = f"{operation} raised {type(exc).__name__}: {exc}"
    except Exception:  # an exception whose str() fails
        text = f"{operation} raised {type(exc).__name__}"
    return UNKNOWN(text, completed=CompletionStatus.MAYBE)


def _user_exception_reply(operation: str, exc: UserException) -> Reply:
    """The reply for an IDL exception the servant raised; UNKNOWN if it cannot be sent (the
    base class itself, or fields that do not fit their types)."""
    serialize = getattr(exc, "serialize", None)
    if serialize is None:
        return system_exception_reply(_unknown(operation, exc))
    try:
        return Reply(ReplyStatus.USER_EXCEPTION, serialize(), exc._repo_id)
    except Exception as bad:
        return system_exception_reply(
            UNKNOWN(
                f"{operation} raised {exc._repo_id}, which could not be sent: {bad}",
                completed=CompletionStatus.YES,
            )
        )


def merge_dispatch(*tables: dict[str, Dispatcher]) -> dict[str, Dispatcher]:
    """The dispatch table of a skeleton: its bases' operations, then its own."""
    out: dict[str, Dispatcher] = {}
    for table in tables:
        out.update(table)
    return out


# ---- in-process transport ----------------------------------------------------------------------


class LocalInvoker:
    """An in-process transport for tests and single-process use: requests are marshalled to
    bytes and dispatched to registered servants directly. Oneway requests run in order on a
    worker thread, so the caller does not wait for them, as over a network."""

    def __init__(self, endpoint: str = "inproc://local") -> None:
        self.endpoint = endpoint
        self._servants: dict[bytes, Servant] = {}
        self._keys = itertools.count(1)
        self._lock = threading.Lock()
        self._oneway: queue.SimpleQueue[tuple[Servant, str, bytes]] | None = None

    def register(self, servant: Servant, key: bytes | None = None) -> ObjectRef:
        with self._lock:
            if key is None:
                key = f"obj{next(self._keys)}".encode()
            self._servants[key] = servant
        return ObjectRef(servant._repo_id, self.endpoint, key)

    def reference_for(self, servant: Servant) -> ObjectRef:
        with self._lock:
            for key, s in self._servants.items():
                if s is servant:
                    return ObjectRef(servant._repo_id, self.endpoint, key)
        return self.register(servant)

    def stub(self, cls: type[StubT], servant: Servant) -> StubT:
        """A stub of `cls` talking to `servant` through this invoker."""
        return cls(self.reference_for(servant), self)

    def invoke(
        self,
        ref: ObjectRef,
        operation: str,
        body: bytes,
        *,
        oneway: bool = False,
        timeout: float | None = None,
    ) -> Reply | None:
        servant = self._servants.get(ref.key) if ref.endpoint == self.endpoint else None
        if oneway:
            if servant is not None:
                self._oneway_queue().put((servant, operation, bytes(body)))
            return None
        if servant is None:
            return system_exception_reply(OBJECT_NOT_EXIST(f"no object with key {ref.key!r}"))
        reply = servant._invoke(operation, bytes(body), self)
        return Reply(reply.status, bytes(reply.body), reply.repo_id)

    def _oneway_queue(self) -> queue.SimpleQueue[tuple[Servant, str, bytes]]:
        with self._lock:
            if self._oneway is None:
                self._oneway = queue.SimpleQueue()
                threading.Thread(
                    target=self._run_oneway, args=(self._oneway,), name="oneway", daemon=True
                ).start()
            return self._oneway

    def _run_oneway(self, requests: queue.SimpleQueue[tuple[Servant, str, bytes]]) -> None:
        while True:
            servant, operation, body = requests.get()
            servant._invoke(operation, body, self)  # a oneway call's reply goes nowhere
