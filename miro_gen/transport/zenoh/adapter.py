"""The server side of calls over Zenoh: one queryable serving all of a process's objects.

The queryable is declared on the key of the process's session (`keys.call_key`) with a Zenoh
channel (`zenoh.handlers.FifoChannel`), not a Python callback: Zenoh's thread puts each query
in it without taking the GIL, and the process's reader threads wait in the channel's `recv`
(which releases the GIL) and serve what they take on their own thread: one thread switch,
done in Rust, between Zenoh and the servant, where a callback took the GIL on Zenoh's thread
and then handed the query to a worker (bench/README.md, "Calls without the callback").

A reader runs an operation marked `@nonblocking` at once; any other call needs one of
`workers` (16) slots: a reader that gets one runs the servant itself, otherwise the call waits
in a queue for the next reader that finishes one. There is always one reader more than slots
(readers are started as calls take slots), so a query is read while every slot is held by a
servant that blocks or calls a service that calls back into this process: the session's
reading never waits for a servant, and `@nonblocking` calls are answered then too. Nothing
runs on Zenoh's thread. The process says it is up with a liveliness token (`keys.alive_key`),
which its callers watch.

As over ZeroMQ (transport.rpc.adapter): a request that does not parse is logged and dropped, one
for an unknown object gets OBJECT_NOT_EXIST, one for an operation the object lacks
BAD_OPERATION, one that waited for a slot until its caller stopped waiting is not run, and once
the server drains, new requests are TRANSIENT (completed NO). With `identify_callers`, servants
learn who calls (`transport.rpc.caller.current()`): over Zenoh that is the principal `zenoh`,
not verified, unless `caller_of` tells it from the key a query came on (the registry's keys
per owner, which the router's access control lets only that owner ask: transport.zenoh.access;
`serve_also` declares them, each with a channel and a reader of its own).
"""

from __future__ import annotations

import atexit
import contextlib
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

from miro_gen.exceptions import BAD_OPERATION, OBJECT_NOT_EXIST, TRANSIENT, CompletionStatus
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime.rpc import Invoker, Reply, Servant, is_nonblocking, system_exception_reply
from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.caller import Caller, serving
from miro_gen.transport.rpc.objects import ObjectTable
from miro_gen.transport.zenoh import keys
from miro_gen.transport.zenoh.session import identity, track, untrack

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)

DEFAULT_WORKERS = 16
JOIN_READERS = 1.0  # seconds close() waits for the readers to leave Zenoh's channel
# Queries Zenoh may hold for the readers; a reader is always free to take them, so this fills
# only when the process gets no CPU at all, and then Zenoh's thread waits (back-pressure).
CHANNEL_DEPTH = 4096
FIRST_READERS = 2  # readers started with the adapter; more as calls take slots
PRINCIPAL = "zenoh"  # who a caller over Zenoh is, as far as the naming table can tell
_CALLER = Caller(PRINCIPAL, False)

_Call = tuple[float, Any, frames.Request, Servant]  # received (monotonic), query, request, servant


class ZenohAdapter(ObjectTable):
    """Serves servants on `session`'s call key; at most `workers` servant calls at once, plus
    the `@nonblocking` ones."""

    def __init__(
        self,
        session: Any,
        invoker: Invoker,
        workers: int = DEFAULT_WORKERS,
        *,
        identify_callers: bool = False,
        caller_of: Callable[[str], Caller | None] | None = None,
    ) -> None:
        super().__init__()  # the object table
        self.session = session
        self.invoker = invoker
        self.zid = identity(session)  # <owner>/<zid>: its keys (transport.zenoh.keys)
        self.endpoint = keys.endpoint(self.zid)
        self._lock = threading.Lock()
        self._identify = identify_callers
        self._caller_of = caller_of  # a query's key -> its caller (None: `zenoh`)
        self._also: list[Any] = []  # queryables on further keys (serve_also)
        self._quick: dict[tuple[type, str], bool] = {}  # (servant class, operation): @nonblocking
        self._slots = workers
        self._busy = 0  # slots held
        self._waiting: deque[_Call] = deque()  # calls for the next slot that frees
        self._readers = 0
        self._threads: list[threading.Thread] = []  # the readers, joined at close
        self._running = 0  # queries taken and not yet answered
        self._idle = threading.Condition(self._lock)
        self._draining = False
        self._closed = False
        self._queryable = track(
            session.declare_queryable(
                keys.call_key(self.zid), zenoh.handlers.FifoChannel(CHANNEL_DEPTH)
            )
        )
        self._channel = self._queryable.handler  # recv() from many threads; ends on undeclare
        with self._lock:
            for _ in range(min(FIRST_READERS, workers + 1)):
                self._start_reader()
        self._token = session.liveliness().declare_token(keys.alive_key(self.zid))
        _adapters.add(self)

    # ---- requests -------------------------------------------------------------------------------

    def _start_reader(self) -> None:
        """One more reader thread (with the lock held)."""
        reader = threading.Thread(target=self._read, name="miro-zenoh-call", daemon=True)
        try:
            reader.start()
        except RuntimeError as e:  # the interpreter is exiting: the readers there are do
            _log.debug("no more reader threads: %s", e)
        else:
            self._readers += 1
            self._threads.append(reader)

    def _read(self, channel: Any = None) -> None:
        """A reader: take queries from Zenoh's channel (the call key's, or `channel`) and serve
        them, until the queryable goes (the channel then says it is closed)."""
        recv = (self._channel if channel is None else channel).recv
        while True:
            try:
                query = recv()
            except zenoh.ZError:  # undeclared: no more queries
                return
            self._serve(query, time.monotonic())
            del query

    def _serve(self, query: Any, received: float) -> None:
        """Answer what needs no servant, run a `@nonblocking` operation, and any other in a
        slot of this thread's or, when all are held, after a slot frees. Never waits."""
        with self._lock:
            self._running += 1
        handed = False
        try:
            call = self._accept(query)
            if call is None:
                return
            req, servant, quick = call
            if quick:
                self._run(query, req, servant, received)
                return
            with self._lock:
                if self._busy >= self._slots:
                    self._waiting.append((received, query, req, servant))
                    handed = True
                    return
                self._busy += 1
                if self._readers <= self._busy and self._readers <= self._slots:
                    self._start_reader()  # one reader is always free to read
            handed = True  # _in_slot answers it and counts it done
            self._in_slot((received, query, req, servant))
        except zenoh.ZError as e:  # the caller or the session went away
            _log.debug("a reply was not sent: %s", e)
        except Exception:
            _log.exception("serving a call failed")
        finally:
            if not handed:
                query.drop()  # its caller hears that no more replies come
                self._done()

    def _in_slot(self, call: _Call | None) -> None:
        """Run `call` in the slot this thread holds, then the calls waiting for one; then let
        the slot go."""
        while call is not None:
            received, query, req, servant = call
            try:
                self._run(query, req, servant, received)
            except zenoh.ZError as e:  # the caller or the session went away
                _log.debug("a reply was not sent: %s", e)
            except Exception:
                _log.exception("serving a call failed")
            finally:
                query.drop()  # now, not when the last reference goes: its caller hears the end
                del query, call
                self._done()
            with self._lock:
                if self._waiting:
                    call = self._waiting.popleft()
                else:
                    self._busy -= 1
                    call = None

    def _done(self) -> None:
        with self._lock:
            self._running -= 1
            if not self._running:
                self._idle.notify_all()

    def _accept(self, query: Any) -> tuple[frames.Request, Servant, bool] | None:
        """The request `query` carries, its servant and whether the operation is @nonblocking;
        None when it was dropped or answered already (a bad frame, draining, no such object or
        operation)."""
        attachment = query.attachment
        if attachment is None or query.payload is None:
            _peer_warnings.warning("dropped a request without a header or a body")
            return None
        try:
            req = frames.decode_request(attachment.to_bytes())
        except frames.FrameError as e:
            _peer_warnings.warning("dropped a request: %s", e)
            return None
        if self._draining:
            busy = TRANSIENT(f"{self.endpoint} is stopping", completed=CompletionStatus.NO)
            self._reply(query, req, system_exception_reply(busy))
            return None
        servant = self.servant(req.key)
        if servant is None:
            missing = OBJECT_NOT_EXIST(f"no object with key {req.key!r} at {self.endpoint}")
            self._reply(query, req, system_exception_reply(missing))
            return None
        if req.operation not in servant._dispatch:
            unknown = BAD_OPERATION(
                f"{servant._repo_id} has no operation '{req.operation[:100]}'",
                completed=CompletionStatus.NO,
            )
            self._reply(query, req, system_exception_reply(unknown))
            return None
        kind = (type(servant), req.operation)
        quick = self._quick.get(kind)
        if quick is None:
            if len(self._quick) >= 4096:  # operations are checked against _dispatch: bounded
                self._quick.clear()
            quick = self._quick[kind] = is_nonblocking(servant, req.operation)
        return req, servant, quick

    def _run(self, query: Any, req: frames.Request, servant: Servant, received: float) -> None:
        """Run the servant for `req`, which arrived at `received` (monotonic seconds), and
        answer `query`."""
        if req.timeout_ms and time.monotonic() - received > req.timeout_ms / 1000:
            return  # its caller gave up: not run
        body = query.payload.to_bytes()
        if self._identify:
            who = None if self._caller_of is None else self._caller_of(str(query.key_expr))
            with serving(who or _CALLER):
                reply = servant._invoke(req.operation, body, self.invoker)
        else:
            reply = servant._invoke(req.operation, body, self.invoker)
        self._reply(query, req, reply)

    @staticmethod
    def _reply(query: Any, req: frames.Request, reply: Reply) -> None:
        if req.oneway:
            return
        header = frames.reply_header(req.request_id, reply.status, reply.repo_id)
        query.reply(query.key_expr, reply.body, attachment=header)

    def serve_also(self, key_expr: str) -> None:
        """Serve this process's objects on the keys of `key_expr` too, through a channel with
        a reader of its own (its calls take the same slots)."""
        channel: Any = zenoh.handlers.FifoChannel(CHANNEL_DEPTH)
        queryable = track(self.session.declare_queryable(key_expr, channel))
        self._also.append(queryable)
        reader = threading.Thread(
            target=self._read, args=(queryable.handler,), name="miro-zenoh-call", daemon=True
        )
        reader.start()
        with self._lock:
            self._threads.append(reader)

    # ---- the end --------------------------------------------------------------------------------

    def drain(self, timeout: float) -> bool:
        """Refuse new requests (TRANSIENT, completed NO) and wait up to `timeout` seconds for
        the calls being served to finish and be answered; whether they all were. Queries still
        in Zenoh's channel then are answered TRANSIENT here."""
        deadline = time.monotonic() + timeout
        with self._lock:
            self._draining = True
            while self._running:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(left)
        for channel in (self._channel, *(q.handler for q in self._also)):
            with contextlib.suppress(zenoh.ZError):  # closed: nothing is left in it
                while (query := channel.try_recv()) is not None:
                    self._serve(query, time.monotonic())
                    del query
        return True

    def close(self) -> None:
        """Stop serving: the queryable and the liveliness token go; the readers end once
        Zenoh's channel is empty and closed."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        untrack(self._queryable)
        for queryable in self._also:
            untrack(queryable)
        with contextlib.suppress(zenoh.ZError):  # the session is closed already
            self._token.undeclare()
        self._join_readers(JOIN_READERS)

    def _join_readers(self, timeout: float) -> None:
        """Wait up to `timeout` seconds for the readers that wait in Zenoh's channel to see it
        closed and end: one still inside Zenoh's `recv` when the interpreter finalizes is
        unwound through Rust frames, and the process aborts ("FATAL: exception not
        rethrown") instead of exiting with its status."""
        deadline = time.monotonic() + timeout
        me = threading.current_thread()
        with self._lock:
            readers = list(self._threads)
        for reader in readers:
            if reader is not me:
                reader.join(max(0.0, deadline - time.monotonic()))


_adapters: weakref.WeakSet[ZenohAdapter] = weakref.WeakSet()


def _close_all() -> None:
    """At exit, before the session module undeclares what is left: every adapter still open
    is closed and its readers joined (see `_join_readers`)."""
    for adapter in list(_adapters):
        adapter.close()


atexit.register(_close_all)  # after transport.zenoh.session's: atexit runs it first
