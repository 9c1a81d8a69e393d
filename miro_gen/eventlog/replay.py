"""A supplier that sends events already encoded, with the stamps they were recorded with.

A player must publish each logged event as its original supplier did: same domain, type name,
type hash, sequence number and source stamp, the CDR payload untouched. `ReplaySupplier` is a
`StructuredPushSupplier` (its socket, its connection to the channel, its `push()` for the
player's own events) with `push_encoded()` for those. Like `push()`, it may be called from any
thread. Each event is due at a moment (the player's clock), so `push_encoded()` sends it at
once, on the calling thread, through a direct link (transport.events.links): a turn of the
reactor would be a hand-off to another thread, which wakes up when the scheduler and the
interpreter's lock let it (a bare publisher makes no such hand-off). Over a backbone whose
links are not direct (Zenoh), the events wait for the reactor's next turn instead and leave
in one frame per run of events of one topic, type hash and supplier.

Keep-all consumers of this host return credits (transport.events.credits), and the replay
honours them as suppliers do, through the same `TopicCredits` (one per replayed topic and
recorded supplier, sharing one window: the channel's queue toward a consumer holds all their
frames): before a direct send, the calling thread (the player's) waits until the frame may
go, at most shm.WAIT_KEEP_ALL seconds for a consumer that returns none (dead, stopped), which
is then not waited for until it returns a credit again. So a keep-all consumer receives every
replayed event, in order, at any rate: the player's clock waits for it instead
(eventlog.player). Keep-last consumers are not waited for.
"""

from __future__ import annotations

import threading
from typing import NamedTuple

from miro_gen.transport.events import MAX_BATCH_BYTES, EventChannel, StructuredPushSupplier
from miro_gen.transport.events.credits import FREE, GAVE_UP, TopicCredits, share_window
from miro_gen.transport.events.frames import (
    BATCH_HEADER,
    EVENT_HEADER,
    MAX_EVENTS,
    pack_batch,
    topic,
)


class _Encoded(NamedTuple):
    domain: str
    type_name: str
    type_hash: str
    supplier: int
    seq: int
    stamp_ns: int
    publish_ns: int
    data: bytes


class ReplaySupplier(StructuredPushSupplier):
    """Publishes pre-encoded events into `channel` (and, with `push()`, its own)."""

    def __init__(self, channel: EventChannel, domain_name: str | None = None) -> None:
        super().__init__(channel, domain_name, direct=True)
        self.direct = getattr(self.link, "direct", False)
        self._pending: list[_Encoded] = []
        self._pending_lock = threading.Lock()
        self._scheduled = False
        self.replayed = 0
        self.replay_dropped = 0
        # Keep-all consumers' credits by (topic frame, recorded supplier id), the events that
        # waited for one, and those sent after giving a consumer up (dead, or silent for
        # shm.WAIT_KEEP_ALL s): those may be lost to it.
        self._credits: dict[tuple[bytes, int], TopicCredits] = {}
        self.replay_waited = 0
        self.replay_unwaited = 0

    def push_encoded(
        self,
        domain: str,
        type_name: str,
        type_hash: str,
        supplier: int,
        seq: int,
        stamp_ns: int,
        publish_ns: int,
        data: bytes,
    ) -> None:
        """Send (or queue) one event as it was recorded: `data` is its CDR payload."""
        event = _Encoded(domain, type_name, type_hash, supplier, seq, stamp_ns, publish_ns, data)
        if self.direct:
            with self._pending_lock:  # one sender at a time: the counts stay right
                self._send_encoded([event])
            return
        with self._pending_lock:
            self._pending.append(event)
            schedule = not self._scheduled
            self._scheduled = True
        if schedule:
            self.reactor.call_soon(self._send_pending)

    def has_subscribers_for(self, domain: str, type_name: str) -> bool:
        """Whether a consumer of the channel subscribes to events of `type_name` from
        `domain` (this supplier replays many domains; `has_subscribers` knows its own)."""
        frame = topic(domain, type_name)
        return any(frame.startswith(p) for p in list(self._subscriptions))

    def _send_pending(self) -> None:
        with self._pending_lock:
            pending, self._pending = self._pending, []
            self._scheduled = False
        self._send_encoded(pending)

    def _send_encoded(self, pending: list[_Encoded]) -> None:
        run: list[_Encoded] = []
        size = 0
        for e in pending:
            if BATCH_HEADER + EVENT_HEADER + len(e.data) > self.max_frame:  # too large to send
                self.replay_dropped += 1
                continue
            if run and (
                (e.domain, e.type_name, e.type_hash, e.supplier)
                != (run[0].domain, run[0].type_name, run[0].type_hash, run[0].supplier)
                or len(run) == MAX_EVENTS
                or size + len(e.data) > MAX_BATCH_BYTES
            ):
                self._send_run(run)
                run, size = [], 0
            run.append(e)
            size += len(e.data)
        if run:
            self._send_run(run)

    def _send_run(self, run: list[_Encoded]) -> None:
        first = run[0]
        frame = topic(first.domain, first.type_name)
        body = pack_batch(
            first.supplier,
            first.type_hash,
            [(e.seq, e.stamp_ns, e.publish_ns, e.data) for e in run],
        )
        credits = self._credited(frame, first)
        if credits is not None:
            waited = credits.wait_for_room(first.supplier, self._closing)
            if waited == GAVE_UP:
                self.replay_unwaited += len(run)
            elif waited != FREE:
                self.replay_waited += len(run)
        if self._send_frame(frame, body):
            self.replayed += len(run)
            if credits is not None:
                credits.sending(first.seq, run[-1].seq)
        else:  # at the high-water mark: dropped, as a live supplier's would be
            self.replay_dropped += len(run)

    def _credited(self, frame: bytes, first: _Encoded) -> TopicCredits | None:
        """The credits of the keep-all consumers of this host that take `frame`, when the
        calling thread may wait for them (a direct send, not on the reactor thread)."""
        if not (self.direct and self._keep_all.marker) or self.reactor.in_reactor_thread():
            return None
        key = (frame, first.supplier)
        credits = self._credits.get(key)
        if credits is None:
            credits = self._credits[key] = TopicCredits(frame, first.type_name, self.window)
        if credits.update(self._keep_all, self._generation):  # the replayed topics share it
            share_window(self._credits.values(), self.window)
        return credits if credits.readers else None

    def _closing(self) -> bool:
        return bool(self.reactor.closed) or not self._connected
