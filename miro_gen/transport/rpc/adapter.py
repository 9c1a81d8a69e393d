"""The server side of remote calls: one ROUTER socket serving all of a process's objects.

The socket is served by a leader/followers group of threads (`miro_gen.transport.rpc.dispatch`):
the thread that receives a request runs its servant and sends the reply, and another thread
takes over the socket when a servant blocks, so a servant may wait (for the next value) or call
another service that calls back into this one (A -> B -> A) without stopping the process from
serving. Methods marked `@nonblocking` always run on the receiving thread. The reactor runs no
servant code. A frame that does not parse is logged and dropped; a request for an unknown
object gets OBJECT_NOT_EXIST, one for an operation the object does not have BAD_OPERATION
(before anything about it is kept: a peer must not grow this process's memory with made-up
names); a request that waited for a free thread until its caller stopped waiting is not run.
Requests waiting for a thread are bounded in number and bytes; a reply larger than the maximum
message size becomes MARSHAL. An ok reply of `shm.THRESHOLD` bytes or more to a caller on this
host that takes them goes through the adapter's pool of shared memory (`rpc.shared`) when a
slot is free, the skeleton's encoder copied straight in; a caller's request body in its own
pool is copied out as it is received (a MARSHAL, completed NO, when it cannot be read).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Sequence

import zmq

from miro_gen.exceptions import (
    BAD_OPERATION,
    MARSHAL,
    OBJECT_NOT_EXIST,
    TRANSIENT,
    CompletionStatus,
)
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime.cdr import Encoder
from miro_gen.runtime.rpc import (
    Invoker,
    Reply,
    ReplyStatus,
    Servant,
    is_nonblocking,
    system_exception_reply,
)
from miro_gen.transport import shm, sockets
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.caller import Caller, caller_of, serving
from miro_gen.transport.rpc.dispatch import Dispatcher, Peer
from miro_gen.transport.rpc.objects import ObjectTable
from miro_gen.transport.rpc.shared import BodyPool, SharedRequests, server_marker, unreadable

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

DEFAULT_WORKERS = 16
MAX_PENDING = 10_000  # requests queued for workers; beyond this, TRANSIENT (try again later)
MAX_PENDING_BYTES = 256 << 20  # and bytes of their bodies


class ObjectAdapter(ObjectTable):
    """Serves servants on `bind` (a ZeroMQ endpoint, port `*` for any free one) and on the
    endpoints `also_bind` gives for the one bound, advertising `host` as the address other
    processes reach it at; at most `workers` servant calls run at once. `reactor` gives the
    ZeroMQ context. With `identify_callers`, servants learn who calls them
    (`transport.rpc.caller.current()`). With `serve=False` the socket is bound but nothing is
    read from it until `serve()`: a process whose objects have well-known keys activates them
    first, so an early caller waits instead of hearing OBJECT_NOT_EXIST."""

    def __init__(
        self,
        reactor: Reactor,
        invoker: Invoker,
        bind: str = "tcp://127.0.0.1:*",
        host: str | None = None,
        workers: int = DEFAULT_WORKERS,
        *,
        also_bind: Callable[[str], Sequence[str]] | None = None,
        identify_callers: bool = False,
        serve: bool = True,
    ) -> None:
        super().__init__()  # the object table
        self.reactor = reactor
        self.invoker = invoker
        self.socket = sockets.listening_socket(reactor.context, zmq.ROUTER)
        self.socket.setsockopt(zmq.ROUTER_HANDOVER, 1)
        hwm = sockets.queue_limit(reactor.context)
        self.socket.setsockopt(zmq.RCVHWM, hwm)
        self.socket.setsockopt(zmq.SNDHWM, hwm)
        self.max_message_size = sockets.policy(reactor.context).max_message_size
        # large replies to callers on this host (none mapped before the first), and large
        # requests from them, in their pools: it says so in its routing id, which each caller
        # learns in the connection's handshake
        self.pool = BodyPool(self.max_message_size) if shm.enabled() else None
        self.requests = SharedRequests() if self.pool is not None else None
        if self.requests is not None:
            self.socket.setsockopt(zmq.ROUTING_ID, server_marker())
        self.socket.bind(bind)
        self.bound = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)  # what it listens on
        self.also_bound = list(also_bind(self.bound)) if also_bind is not None else []
        for endpoint in self.also_bound:
            self.socket.bind(endpoint)
        self.endpoint = _advertised(self.bound, host)
        self._quick: dict[tuple[type, str], bool] = {}  # (servant class, operation): @nonblocking
        self._workers = workers
        self._identify = identify_callers
        self._dispatcher: Dispatcher | None = None
        if serve:
            self.serve()

    def serve(self) -> None:
        """Start reading requests (once); from here on the socket belongs to the dispatcher's
        threads."""
        if self._dispatcher is None:
            self._dispatcher = Dispatcher(
                self.socket,
                self._receive,
                self._workers,
                MAX_PENDING,
                MAX_PENDING_BYTES,
                identify=self._identify,
            )

    # ---- requests (on the thread that owns the socket) ------------------------------------------

    def _receive(self, parts: list[bytes], peer: Peer | None) -> _Call | list[bytes] | None:
        """A message (and what is known of its sender, when this adapter identifies callers):
        the call to run, an immediate reply, or None (dropped)."""
        if len(parts) != 3:
            _peer_warnings.warning("dropped a request of %d frames", len(parts) - 1)
            return None
        routing, header, body = parts
        try:
            req = frames.decode_request(header)
        except frames.FrameError as e:
            _peer_warnings.warning("dropped a request: %s", e)
            return None
        if req.shared:  # the body is in the caller's pool: copied out now, its slot back
            data = self._shared_body(routing, body)
            if data is None:
                return _reply_frames(
                    routing, req, system_exception_reply(unreadable(req.operation))
                )
            body = data
        servant = self.servant(req.key)
        if servant is None:
            missing = OBJECT_NOT_EXIST(f"no object with key {req.key!r} at {self.endpoint}")
            return _reply_frames(routing, req, system_exception_reply(missing))
        if req.operation not in servant._dispatch:  # answered before anything is cached
            unknown = BAD_OPERATION(
                f"{servant._repo_id} has no operation '{req.operation[:100]}'",
                completed=CompletionStatus.NO,
            )
            return _reply_frames(routing, req, system_exception_reply(unknown))
        kind = (type(servant), req.operation)
        quick = self._quick.get(kind)
        if quick is None:
            quick = self._quick[kind] = is_nonblocking(servant, req.operation)
        caller = None if peer is None else caller_of(*peer)
        return _Call(self, servant, routing, req, body, kind, quick, caller)

    def _shared_body(self, routing: bytes, descriptor: bytes) -> bytes | None:
        """A request body in the shared memory of the caller `routing`; None when it cannot be
        read (never part of one: the generation is checked after the copy)."""
        if self.requests is None or self.pool is None or not self.pool.takes(routing):
            return None  # not a caller of this host, or shared memory is off here
        return self.requests.body(descriptor, self.max_message_size)

    def drain(self, timeout: float) -> bool:
        """Refuse new requests (TRANSIENT, completed NO) and wait up to `timeout` seconds for
        the calls being served to finish and be answered; whether they all were."""
        return self._dispatcher.drain(timeout) if self._dispatcher is not None else True

    def close(self) -> None:
        """Stop serving (from any thread; the socket closes when its owner is free)."""
        if self._dispatcher is None:
            self.socket.close(linger=0)
        else:
            self._dispatcher.close()
        if self.pool is not None:  # callers that mapped it keep what they map
            self.pool.close()
        if self.requests is not None:
            self.requests.close()


class _Call:
    """One request to run: a dispatcher task."""

    __slots__ = (
        "adapter",
        "body",
        "caller",
        "kind",
        "peer",
        "quick",
        "received",
        "request",
        "servant",
        "size",
    )

    def __init__(
        self,
        adapter: ObjectAdapter,
        servant: Servant,
        peer: bytes,
        request: frames.Request,
        body: bytes,
        kind: Hashable,
        quick: bool,
        caller: Caller | None = None,
    ) -> None:
        self.adapter = adapter
        self.caller = caller
        self.servant = servant
        self.peer = peer
        self.request = request
        self.body = body
        self.kind = kind
        self.quick = quick
        self.size = len(body)
        self.received = time.monotonic() if request.timeout_ms and not quick else 0.0

    def late(self) -> bool:
        timeout_ms = self.request.timeout_ms
        return bool(timeout_ms) and time.monotonic() - self.received > timeout_ms / 1000

    def run(self) -> list[bytes] | None:
        req = self.request
        servant, invoker = self.servant, self.adapter.invoker
        if self.caller is None:
            result = servant._result(req.operation, self.body, invoker)
        else:  # a servant that asks who calls (transport.rpc.caller.current)
            with serving(self.caller):
                result = servant._result(req.operation, self.body, invoker)
        if isinstance(result, Reply):  # an exception
            return self._framed(result, len(result.body))
        size = result.size if isinstance(result, Encoder) else len(result)
        pool = self.adapter.pool
        if (
            pool is not None
            and shm.THRESHOLD <= size <= self.adapter.max_message_size
            and not req.oneway
            and pool.takes(self.peer)
        ):  # the encoder's parts copied straight into a slot: never joined into one body
            if not isinstance(result, Encoder) and type(result) is not bytes:
                result = bytes(result)  # a hand-written table's bytearray or view
            descriptor = pool.put(result)
            if descriptor is not None:
                return [self.peer, frames.shared_reply_header(req.request_id), descriptor]
        body = result.value() if isinstance(result, Encoder) else result
        return self._framed(Reply(ReplyStatus.OK, body), size)

    def _framed(self, reply: Reply, size: int) -> list[bytes] | None:
        """The frames of `reply` (of `size` bytes), or of MARSHAL when it is larger than the
        maximum message size."""
        limit = self.adapter.max_message_size
        if size > limit:
            too_large = MARSHAL(
                f"the reply to {self.request.operation} is {size} bytes, more than the "
                f"maximum message size ({limit}; --max-message-size)",
                completed=CompletionStatus.YES,
            )
            reply = system_exception_reply(too_large)
        return _reply_frames(self.peer, self.request, reply)

    def refuse(self, why: str = "is overloaded") -> list[bytes] | None:
        busy = TRANSIENT(f"{self.adapter.endpoint} {why}", completed=CompletionStatus.NO)
        return _reply_frames(self.peer, self.request, system_exception_reply(busy))


def _reply_frames(peer: bytes, req: frames.Request, reply: Reply) -> list[bytes] | None:
    if req.oneway:
        return None
    body = reply.body  # a skeleton's bytes (only a caller's received replies are views)
    if type(body) is not bytes:
        body = bytes(body)
    return [peer, frames.reply_header(req.request_id, reply.status, reply.repo_id), body]


def _advertised(bound: str, host: str | None) -> str:
    """The endpoint others connect to: the bound one, with `host` instead of the address it is
    bound on when given (a server bound on 0.0.0.0 must advertise a reachable address)."""
    proto, _, rest = bound.partition("://")
    address, _, port = rest.rpartition(":")
    if host:
        address = f"[{host}]" if ":" in host and not host.startswith("[") else host
    elif address in ("0.0.0.0", "[::]", "*"):
        address = "127.0.0.1"
    return f"{proto}://{address}:{port}"
