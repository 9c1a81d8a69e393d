"""The server side of remote calls: one ROUTER socket serving all of a process's objects.

Requests arrive on the reactor thread, which runs no servant code unless told it is quick (a
method marked `@nonblocking`): each request goes to a bounded pool of worker threads, so a servant
may block (wait for the next value) or call another service that calls back into this one
(A -> B -> A) without stopping the process from serving. The reply is handed back to the reactor
thread, which alone touches the socket. A frame that does not parse
is logged and dropped; a request for an unknown object gets OBJECT_NOT_EXIST; a request whose
caller has stopped waiting by the time a worker is free is not run.
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import zmq

from miro_gen.exceptions import OBJECT_NOT_EXIST, TRANSIENT, CompletionStatus
from miro_gen.log import logger
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import (
    Invoker,
    Reply,
    Servant,
    is_nonblocking,
    system_exception_reply,
)
from miro_gen.transport import frames
from miro_gen.transport.reactor import Reactor

_log = logger("MIRO")

DEFAULT_WORKERS = 16
MAX_PENDING = 10_000  # requests queued for workers; beyond this, TRANSIENT (try again later)


class ObjectAdapter:
    """Serves servants on `bind` (a ZeroMQ endpoint, port `*` for any free one), advertising
    `host` as the address other processes reach it at."""

    def __init__(
        self,
        reactor: Reactor,
        invoker: Invoker,
        bind: str = "tcp://127.0.0.1:*",
        host: str | None = None,
        workers: int = DEFAULT_WORKERS,
    ) -> None:
        self.reactor = reactor
        self.invoker = invoker
        self.socket = reactor.context.socket(zmq.ROUTER)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.ROUTER_HANDOVER, 1)
        self.socket.setsockopt(zmq.HEARTBEAT_IVL, 500)
        self.socket.setsockopt(zmq.HEARTBEAT_TIMEOUT, 2000)
        self.socket.bind(bind)
        bound = self.socket.getsockopt_string(zmq.LAST_ENDPOINT)
        self.endpoint = _advertised(bound, host)
        self._servants: dict[bytes, Servant] = {}
        self._keys = itertools.count(1)
        self._prefix = f"{os.getpid()}.".encode()
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="miro-worker")
        self._pending = 0
        self._closed = False
        self._inline: dict[tuple[type, str], bool] = {}  # (servant class, operation): @nonblocking
        reactor.call_soon(reactor.register, self.socket, self._readable)

    # ---- objects --------------------------------------------------------------------------------

    def activate(self, servant: Servant, key: bytes | None = None) -> ObjectRef:
        """Serve `servant` under `key` (a fresh one by default); its reference."""
        with self._lock:
            if key is None:
                key = self._prefix + str(next(self._keys)).encode()
            self._servants[key] = servant
        return ObjectRef(servant._repo_id, self.endpoint, key)

    def deactivate(self, key: bytes) -> None:
        with self._lock:
            self._servants.pop(key, None)

    def servants(self) -> list[tuple[bytes, Servant]]:
        """(key, servant) of every object served here."""
        with self._lock:
            return list(self._servants.items())

    def reference_for(self, servant: Servant) -> ObjectRef:
        """The reference of a servant, activating it on first use."""
        with self._lock:
            for key, s in self._servants.items():
                if s is servant:
                    return ObjectRef(servant._repo_id, self.endpoint, key)
        return self.activate(servant)

    # ---- requests (reactor thread) --------------------------------------------------------------

    def _readable(self) -> None:
        for _ in range(1000):  # then let timers and other sockets have a turn
            try:
                parts = self.socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            self._request(parts)

    def _request(self, parts: list[bytes]) -> None:
        if len(parts) != 3:
            _log.warning("dropped a request of %d frames", len(parts) - 1)
            return
        peer, header, body = parts
        try:
            req = frames.decode_request(header)
        except frames.FrameError as e:
            _log.warning("dropped a request: %s", e)
            return
        with self._lock:
            servant = self._servants.get(req.key)
        if servant is None:
            self._reply(
                peer,
                req,
                system_exception_reply(
                    OBJECT_NOT_EXIST(f"no object with key {req.key!r} at {self.endpoint}")
                ),
            )
            return
        if self._pending >= MAX_PENDING:
            self._reply(
                peer,
                req,
                system_exception_reply(
                    TRANSIENT(f"{self.endpoint} is overloaded", completed=CompletionStatus.NO)
                ),
            )
            return
        kind = (type(servant), req.operation)
        inline = self._inline.get(kind)
        if inline is None:
            inline = self._inline[kind] = is_nonblocking(servant, req.operation)
        if inline:
            self._reply(peer, req, servant._invoke(req.operation, body, self.invoker))
            return
        self._pending += 1
        received = time.monotonic()
        self._pool.submit(self._work, servant, peer, req, body, received)

    # ---- workers --------------------------------------------------------------------------------

    def _work(
        self, servant: Servant, peer: bytes, req: frames.Request, body: bytes, received: float
    ) -> None:
        reply = None
        try:
            late = req.timeout_ms and time.monotonic() - received > req.timeout_ms / 1000
            if late:  # the caller has given up: running it now would surprise everyone
                _log.notice("skipped %s: its caller stopped waiting", req.operation)
                return
            reply = servant._invoke(req.operation, body, self.invoker)
        finally:  # one hand-off back to the reactor thread per request
            self.reactor.call_soon(self._done, peer, req, reply)

    def _done(self, peer: bytes, req: frames.Request, reply: Reply | None) -> None:
        self._pending -= 1
        if reply is not None:
            self._reply(peer, req, reply)

    def _reply(self, peer: bytes, req: frames.Request, reply: Reply) -> None:
        if req.oneway or self._closed:
            return
        head = frames.encode_reply(frames.Reply(req.request_id, reply.status, reply.repo_id))
        try:
            self.socket.send_multipart([peer, head, reply.body], zmq.NOBLOCK)
        except zmq.ZMQError as e:  # the caller is gone: nobody to tell
            _log.notice("could not reply to %s: %s", req.operation, e)

    def close(self) -> None:
        """Stop serving (from the reactor thread, or after the reactor has stopped)."""
        self._closed = True
        self.reactor.unregister(self.socket)
        self._pool.shutdown(wait=False, cancel_futures=True)
        self.socket.close(0)


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
