"""Calls from a notification channel to its CORBA clients: events to each push consumer, and
offer and subscription changes to them and to the suppliers.

Each push consumer has a `Pusher`: a thread of its own and a bounded queue (its depth and what a
full queue drops are its QoS: `qos.py`; at most QUEUE_BYTES whatever the depth), so a slow or
dead consumer holds up nobody else. A consumer that fails `MAX_FAILURES` pushes in a row (its
process killed: connections refused; hung: each push times out after `PUSH_TIMEOUT`) is
dropped: its proxy disconnects, as one that says Disconnected is at once. A push that fails
otherwise (the consumer raised) costs that event only.

Suppliers are told of subscription changes by the channel's `Notifier`, one thread for all of
them, each call bounded by `NOTIFY_TIMEOUT`; what each was told is remembered, so changes are
sent as differences and never queue up (a supplier that fails `MAX_FAILURES` calls in a row is
told nothing more).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from miro_gen.corba.notify.wire import EventType, write_event_types
from miro_gen.corba.servants import HEADER
from miro_gen.exceptions import (
    COMM_FAILURE,
    OBJECT_NOT_EXIST,
    TIMEOUT,
    TRANSIENT,
    SystemException,
)
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.cdrstream import CdrOutput

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)

MAX_FAILURES = 3  # calls in a row that find a client gone before it is dropped
PUSH_TIMEOUT = 5.0  # seconds a consumer may take to take one event
NOTIFY_TIMEOUT = 2.0  # seconds a client may take to take a change of offers or subscriptions
RETRY_PAUSE = 0.05  # seconds between two calls to a client that failed, doubling
QUEUE_BYTES = 64 << 20  # of events waiting for one consumer, whatever its depth
_GONE = (TRANSIENT, COMM_FAILURE, TIMEOUT, OBJECT_NOT_EXIST)
_DISCONNECTED = "IDL:omg.org/CosEventComm/Disconnected:1.0"


def changes_body(added: list[EventType], removed: list[EventType]) -> bytes:
    """The request body of offer_change / subscription_change."""
    out = CdrOutput()
    write_event_types(out, added)
    write_event_types(out, removed)
    return HEADER + out.buf


class Told:
    """What a client has been told of a set of event types, and whether it wants to know."""

    def __init__(self) -> None:
        self.types: frozenset[EventType] = frozenset()
        self.updates = True
        self.failures = 0

    def change(self, now: frozenset[EventType]) -> bytes | None:
        """The body of a change call bringing the client up to `now` (None: nothing to say)."""
        if not self.updates or now == self.types:
            return None
        added, removed = sorted(now - self.types), sorted(self.types - now)
        self.types = now
        return changes_body(added, removed)


class Consumer(Protocol):
    """What a pusher asks of the proxy it pushes for."""

    name: str

    def request(self, event: Any) -> tuple[str, bytes]:
        """The operation and body that deliver `event`."""
        ...

    def pending_change(self) -> bytes | None:
        """An offer_change body to send first, if the offers changed."""
        ...

    def gone(self, why: str) -> None:
        """The consumer is gone (or said Disconnected): disconnect it."""
        ...


class Pusher:
    """Pushes the events given to `put` to one consumer (`ref`), in order, from its own
    thread; at most `depth` wait, the oldest (or with `drop_newest`, the newest) dropped."""

    def __init__(
        self, invoker: Any, ref: ObjectRef, consumer: Consumer, depth: int, drop_newest: bool
    ) -> None:
        self.invoker = invoker
        self.ref = ref
        self.consumer = consumer
        self.depth = depth
        self.drop_newest = drop_newest
        self.pushed = 0
        self.dropped = 0
        self.failed = 0  # events that did not get through (the consumer raised, or was gone)
        self._queue: deque[Any] = deque()
        self._bytes = 0  # of the events waiting
        self._cond = threading.Condition()
        self._changed = False
        self._closed = False
        self._thread = threading.Thread(
            target=self._run, name=f"miro-notify-push-{consumer.name}", daemon=True
        )
        self._thread.start()

    def put(self, event: Any) -> None:
        size = len(event)
        with self._cond:
            if self._closed:
                return
            while self._queue and (
                len(self._queue) >= self.depth or self._bytes + size > QUEUE_BYTES
            ):
                self.dropped += 1
                if self.drop_newest:
                    return
                self._bytes -= len(self._queue.popleft())
            self._queue.append(event)
            self._bytes += size
            if len(self._queue) == 1:
                self._cond.notify()

    def changed(self) -> None:
        """The offers changed: the consumer is told before its next event."""
        with self._cond:
            self._changed = True
            self._cond.notify()

    def resize(self, depth: int, drop_newest: bool) -> None:
        with self._cond:
            self.depth, self.drop_newest = depth, drop_newest
            while len(self._queue) > depth:
                self._bytes -= len(self._queue.popleft())
                self.dropped += 1

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self.dropped += len(self._queue)
            self._queue.clear()
            self._bytes = 0
            self._cond.notify()

    @property
    def waiting(self) -> int:
        return len(self._queue)

    def _run(self) -> None:
        failures = 0
        while True:
            with self._cond:
                while not (self._queue or self._changed or self._closed):
                    self._cond.wait()
                if self._closed:
                    return
                changed, self._changed = self._changed, False
                event = self._queue.popleft() if self._queue and not changed else None
                if event is not None:
                    self._bytes -= len(event)
            if changed:
                body = self.consumer.pending_change()
                call: tuple[str, bytes] | None = None if body is None else ("offer_change", body)
                timeout = NOTIFY_TIMEOUT
            else:
                call, timeout = self.consumer.request(event), PUSH_TIMEOUT
            if call is None:
                continue
            outcome = self._call(call[0], call[1], timeout)
            if outcome == "ok":
                failures = 0
                if not changed:
                    self.pushed += 1
                continue
            if not changed:
                self.failed += 1
            if outcome == "disconnected":
                self.consumer.gone("said Disconnected")
                return
            if outcome == "gone":
                failures += 1
                if failures >= MAX_FAILURES:
                    self.consumer.gone(f"{failures} pushes in a row found it gone")
                    return
                time.sleep(RETRY_PAUSE * 2 ** (failures - 1))

    def _call(self, operation: str, body: bytes, timeout: float) -> str:
        """'ok', 'gone' (unreachable), 'disconnected' (said so) or 'failed' (raised)."""
        try:
            reply = self.invoker.invoke(self.ref, operation, body, timeout=timeout)
        except _GONE as e:
            _log.debug("%s to %s: %s", operation, self.consumer.name, e)
            return "gone"
        except SystemException as e:
            _peer_warnings.warning("%s to %s failed: %s", operation, self.consumer.name, e)
            return "failed"
        if reply is None or reply.status == rpc.ReplyStatus.OK:
            return "ok"
        if reply.status == rpc.ReplyStatus.USER_EXCEPTION and reply.repo_id == _DISCONNECTED:
            return "disconnected"
        if reply.status == rpc.ReplyStatus.SYSTEM_EXCEPTION and reply.repo_id in (
            OBJECT_NOT_EXIST._repo_id,
        ):
            return "gone"
        _peer_warnings.warning(
            "%s to %s raised %s", operation, self.consumer.name, reply.repo_id or reply.status
        )
        return "failed"


class Notifier:
    """Tells clients of changes to what they follow, on one thread: `watch(key, ref, told,
    now)` registers one (`now()`: the current set), `poke()` wakes the thread to compare."""

    def __init__(self, invoker: Any, operation: str, name: str) -> None:
        self.invoker = invoker
        self.operation = operation
        self._clients: dict[int, tuple[ObjectRef, Told, Callable[[], frozenset[EventType]]]] = {}
        self._cond = threading.Condition()
        self._dirty = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def watch(
        self, key: int, ref: ObjectRef, told: Told, now: Callable[[], frozenset[EventType]]
    ) -> None:
        with self._cond:
            self._clients[key] = (ref, told, now)
            self._dirty = True
            self._cond.notify()

    def forget(self, key: int) -> None:
        with self._cond:
            self._clients.pop(key, None)

    def poke(self) -> None:
        with self._cond:
            self._dirty = True
            self._cond.notify()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not (self._dirty or self._closed):
                    self._cond.wait()
                if self._closed:
                    return
                self._dirty = False
                clients = list(self._clients.values())
            for ref, told, now in clients:
                if told.failures >= MAX_FAILURES:
                    continue
                before = told.types
                body = told.change(now())
                if body is None:
                    continue
                try:
                    self.invoker.invoke(ref, self.operation, body, timeout=NOTIFY_TIMEOUT)
                    told.failures = 0
                except SystemException as e:
                    told.types = before  # not told: the difference is sent again next time
                    told.failures += 1
                    _log.debug("%s: %s", self.operation, e)
                    if told.failures >= MAX_FAILURES:
                        _log.info("a supplier did not take %s: told no more", self.operation)
