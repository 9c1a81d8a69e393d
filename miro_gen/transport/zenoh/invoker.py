"""The client side of calls over Zenoh: the `Invoker` generated stubs call through.

A call is one `get` on the key of the server's session (`keys.call_key`), the request header
(transport.rpc.frames) in its attachment and the CDR body as its payload; the reply carries
the reply header in its attachment. The outcomes are the ZeroMQ invoker's:

* a server whose process is not up (no liveliness token `keys.alive_key`) is TRANSIENT,
  completed NO, before anything is sent: a stub that follows its name looks it up again;
* once the request went out, a call that gets no reply from the server's own session is
  TIMEOUT, completed MAYBE, never sent again (at most once stays at most once), whether
  the time ran out or the server's session went away meanwhile;
* a reply from any other session is dropped: Zenoh lets two sessions declare a queryable on
  the same key (both get the query, since calls go to every match), but only the session
  that the reference names answers for its objects (`Reply.replier_id`).

A call to the naming registry (the router's own session, which answers every request it gets)
that ends without a reply, from a session with a certificate that does not see the router's
liveliness token either (`_unseen`), says that the router's access control
(`miro naming --per-robot`) may deny this certificate that key: Zenoh drops what its access
control denies without a word (transport.zenoh.access). Such a TIMEOUT carries the minor code
of a refused connection, so that the naming client says it as such, and a server stops
waiting for its naming service.

The liveliness of servers is kept by a subscriber whose callback only adds and removes ids in
a set; a server not yet seen is asked for once (`liveliness().get`), from the calling thread.
"""

from __future__ import annotations

import itertools
import threading
import time
from typing import Any

import zenoh

from miro_gen.exceptions import MARSHAL, TIMEOUT, TRANSIENT, CompletionStatus
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Reply, ReplyStatus, Servant
from miro_gen.transport.rpc import frames
from miro_gen.transport.rpc.invoker import REFUSED_MINOR, LocalServants
from miro_gen.transport.zenoh import keys
from miro_gen.transport.zenoh.access import denied_hint
from miro_gen.transport.zenoh.session import direct, identity, track, untrack

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)

CONNECT_TIMEOUT = 2.0  # seconds to learn whether a server not seen before is up
UNSEEN_AFTER = 1.0  # seconds a silent router stays unseen before its access control is blamed
NO_LIMIT = 365 * 86400.0  # a call without a timeout: Zenoh's queries need one
MAX_BODY = 1 << 30  # bytes of a request (a Zenoh message has no smaller limit of ours)
_ALL = zenoh.QueryTarget.ALL
_NO_CONSOLIDATION = zenoh.ConsolidationMode.NONE
_OK = ReplyStatus.OK


class ZenohInvoker:
    """Delivers requests to remote objects over a Zenoh session; safe from any thread. Local
    servants passed as arguments are activated on `adapter` (the process's server side)."""

    def __init__(self, session: Any, adapter: LocalServants | None = None) -> None:
        self.session = session
        self.adapter = adapter
        self.owner = keys.owner_part(identity(session))  # its certificate's name ("": none)
        self._ids = itertools.count(1)
        self._tails: dict[tuple[bytes, str], bytes] = {}
        self._routes: dict[str, tuple[str, str]] = {}  # endpoint: (identity, call key)
        self._alive: set[str] = set()
        self._closed = False
        self._lock = threading.Lock()
        self._watch = track(
            session.liveliness().declare_subscriber(
                keys.ALIVE_ALL, direct(self._on_alive), history=True
            )
        )
        self.foreign_replies = 0  # replies from sessions that do not own the object: dropped

    # ---- liveliness (Zenoh's threads: never block) -------------------------------------------

    def _on_alive(self, sample: Any) -> None:
        zid = keys.zid_of_alive(str(sample.key_expr))
        if zid is None:
            return
        if sample.kind == zenoh.SampleKind.PUT:
            self._alive.add(zid)
        else:
            self._alive.discard(zid)

    def _is_up(self, zid: str) -> bool:
        if zid in self._alive:
            return True
        for reply in self.session.liveliness().get(keys.alive_key(zid), timeout=CONNECT_TIMEOUT):
            if reply.ok is not None:
                self._alive.add(zid)
                return True
        return False

    def _unseen(self, router: str) -> bool:
        """Whether the router `router`, connected and silent to a naming request, stays unseen
        (its process's liveliness token) for a moment: its access control denies this session
        (an allowed session sees its token from the router's start, before its registry
        answers; a router still starting is seen within the moment, and is waited for)."""
        deadline = time.monotonic() + UNSEEN_AFTER
        while self.session.info.routers_zid():
            for reply in self.session.liveliness().get(keys.alive_key(router), timeout=0.5):
                if reply.ok is not None:
                    return False
            if time.monotonic() >= deadline:
                return True
            time.sleep(0.1)
        return False  # gone: not a denial

    def _target(self, endpoint: str) -> str:
        """The identity (transport.zenoh.keys) serving `endpoint`: the router's session (no
        owner) for the naming registry."""
        if keys.is_naming(endpoint):
            routers = self.session.info.routers_zid()
            if not routers:
                raise TRANSIENT("no Zenoh router (the naming service) is connected")
            router = keys.identity("", str(routers[0]))
            self._alive.add(router)  # connected to it: up
            return router
        zid = keys.zid_of(endpoint)
        if zid is None:
            raise TRANSIENT(f"{endpoint!r} is not an endpoint of the Zenoh backbone")
        return zid

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
        if self._closed:
            raise TRANSIENT("the invoker is closed")
        if not ref.endpoint:
            raise TRANSIENT("the object reference has no endpoint (nil reference?)")
        if len(body) > MAX_BODY:
            raise MARSHAL(f"{operation}: the request is too large", completed=CompletionStatus.NO)
        route = self._routes.get(ref.endpoint)
        if route is None:
            zid = self._target(ref.endpoint)
            route = (zid, keys.route_key(ref.endpoint, zid))
            if _cacheable(ref.endpoint):
                if len(self._routes) >= 4096:
                    self._routes.clear()
                self._routes[ref.endpoint] = route
        zid, key = route
        if not self._is_up(zid):
            raise TRANSIENT(f"cannot reach {ref.endpoint} for {operation}: its process is not up")
        wait = timeout if timeout is not None and timeout > 0 else 0.0
        tail = self._tails.get((ref.key, operation))
        if tail is None:
            if len(self._tails) >= 4096:
                self._tails.clear()
            tail = self._tails[(ref.key, operation)] = frames.request_tail(ref.key, operation)
        request_id = next(self._ids)
        header = frames.request_header(tail, request_id, int(wait * 1000), oneway)
        if oneway:
            self.session.get(
                key, _ignore, target=_ALL, consolidation=_NO_CONSOLIDATION,
                payload=body, attachment=header, timeout=wait or CONNECT_TIMEOUT,
            )  # fmt: skip
            return None
        start = time.monotonic()
        replies = self.session.get(
            key, target=_ALL, consolidation=_NO_CONSOLIDATION,
            payload=body, attachment=header, timeout=wait or NO_LIMIT,
        )  # fmt: skip
        for reply in replies:
            found = self._reply(reply, zid, request_id)
            if found is not None:
                return found
        late = wait and time.monotonic() - start >= wait
        if self.owner and keys.is_naming(ref.endpoint) and self._unseen(zid):
            raise TIMEOUT(
                f"{operation}: no reply from the naming service ({ref.endpoint}); "
                f"{denied_hint(self.owner, key)}",
                REFUSED_MINOR,
                CompletionStatus.MAYBE,
            )
        why = "no reply in time" if late else "its process went away"
        raise TIMEOUT(f"{operation}: {why} ({ref.endpoint})", completed=CompletionStatus.MAYBE)

    def _reply(self, reply: Any, zid: str, request_id: int) -> Reply | None:
        """The reply to `request_id` that `reply` is, if the session of the identity `zid`
        sent it."""
        replier = reply.replier_id
        if replier is None or str(replier.zid) != keys.zid_part(zid):
            self.foreign_replies += 1
            _peer_warnings.warning(
                "dropped a reply from %s for an object of %s", replier, zid, key="foreign reply"
            )
            return None
        sample = reply.ok
        if sample is None or sample.attachment is None:
            _peer_warnings.warning("dropped an error reply from %s", zid)
            return None
        try:
            head = frames.decode_reply(sample.attachment.to_bytes())
        except frames.FrameError as e:
            _peer_warnings.warning("dropped a reply from %s: %s", zid, e)
            return None
        if head.request_id != request_id:
            return None
        status = head.status
        return Reply(_OK if status == _OK else ReplyStatus(status), sample.payload.to_bytes(),
                     head.repo_id)  # fmt: skip

    def reference_for(self, servant: Servant) -> ObjectRef:
        if self.adapter is None:
            raise TRANSIENT("a local object can only be passed by a process that serves objects")
        return self.adapter.reference_for(servant)

    def close(self) -> None:
        """Stop watching servers; calls after this fail with TRANSIENT."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        untrack(self._watch)


def _cacheable(endpoint: str) -> bool:
    """Whether the session an endpoint names stays the same: not the naming service's, which
    is whichever router this session is connected to now."""
    return not keys.is_naming(endpoint)


def _ignore(_reply: Any) -> None:
    """A oneway call's replies (there are none)."""
