"""The server side of calls over Zenoh: one queryable serving all of a process's objects.

The queryable is declared on the key of the process's session (`keys.call_key`); its callback
runs on Zenoh's threads: it reads the request header and answers what needs no servant, runs
operations marked `@nonblocking` there (as over ZeroMQ, where they run on the receiving
thread: no thread switch, as raw Zenoh code that replies in its callback), and puts every other
query in a queue. A pool of threads (`workers`, 16 by default) takes queries from there, runs
the servants and replies, so a servant may block or call another service that calls back into
this one (on Zenoh's thread that would stop the session's reading, and a nested call's reply
would never arrive). The process says it is up with a liveliness token (`keys.alive_key`),
which its callers watch.

As over ZeroMQ (transport.rpc.adapter): a request that does not parse is logged and dropped, one
for an unknown object gets OBJECT_NOT_EXIST, one for an operation the object lacks
BAD_OPERATION, one that waited until its caller stopped waiting is not run, and once the
server drains, new requests are TRANSIENT (completed NO). With `identify_callers`, servants
learn who calls (`transport.rpc.caller.current()`): over Zenoh that is the principal
`zenoh`, not verified, unless `caller_of` tells it from the key a query came on (the
registry's keys per owner, which the router's access control lets only that owner ask:
transport.zenoh.access; `serve_also` declares them).
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
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
from miro_gen.transport.zenoh.session import direct, identity, track, untrack

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)

DEFAULT_WORKERS = 16
PRINCIPAL = "zenoh"  # who a caller over Zenoh is, as far as the naming table can tell
_CALLER = Caller(PRINCIPAL, False)


class ZenohAdapter(ObjectTable):
    """Serves servants on `session`'s call key; at most `workers` servant calls at once."""

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
        self._queries: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._quick: dict[tuple[type, str], bool] = {}  # (servant class, operation): @nonblocking
        self._running = 0
        self._idle = threading.Condition(self._lock)
        self._draining = False
        self._closed = False
        self._threads = [
            threading.Thread(target=self._work, name="miro-zenoh-call", daemon=True)
            for _ in range(workers)
        ]
        for t in self._threads:
            t.start()
        self._queryable = track(
            session.declare_queryable(keys.call_key(self.zid), direct(self._arrived))
        )
        self._token = session.liveliness().declare_token(keys.alive_key(self.zid))

    # ---- requests -------------------------------------------------------------------------------

    def _arrived(self, query: Any) -> None:
        """Zenoh's thread: read the header, answer what needs no servant, run an operation
        marked @nonblocking here (as raw Zenoh code replies in its callback: no thread switch),
        and hand everything else to the workers. Never blocks."""
        received = time.monotonic()
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
            else:
                self._queries.put((received, query, req, servant))
                handed = True
        except zenoh.ZError as e:  # the caller or the session went away
            _log.debug("a reply was not sent: %s", e)
        except Exception:
            _log.exception("serving a call failed")
        finally:
            del query  # finalizes the query unless a worker has it
            if not handed:
                self._done()

    def _done(self) -> None:
        with self._lock:
            self._running -= 1
            if not self._running:
                self._idle.notify_all()

    def _work(self) -> None:
        while True:
            item = self._queries.get()
            if item is None:
                return
            received, query, req, servant = item
            try:
                self._run(query, req, servant, received)
            except zenoh.ZError as e:  # the caller or the session went away
                _log.debug("a reply was not sent: %s", e)
            except Exception:
                _log.exception("serving a call failed")
            finally:
                del query, item  # finalizes the query: its caller hears that no more come
                self._done()

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
        """Serve this process's objects on the keys of `key_expr` too."""
        self._also.append(track(self.session.declare_queryable(key_expr, direct(self._arrived))))

    # ---- the end --------------------------------------------------------------------------------

    def drain(self, timeout: float) -> bool:
        """Refuse new requests (TRANSIENT, completed NO) and wait up to `timeout` seconds for
        the calls being served to finish and be answered; whether they all were."""
        deadline = time.monotonic() + timeout
        with self._lock:
            self._draining = True
            while self._running:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(left)
        return True

    def close(self) -> None:
        """Stop serving: the queryable and the liveliness token go, the threads end."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        untrack(self._queryable)
        for queryable in self._also:
            untrack(queryable)
        with contextlib.suppress(zenoh.ZError):  # the session is closed already
            self._token.undeclare()
        for _ in self._threads:
            self._queries.put(None)
