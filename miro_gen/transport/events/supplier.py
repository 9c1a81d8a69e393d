"""Suppliers of an event channel (Miro's StructuredPushSupplier): `push()` from any thread,
events batched per reactor turn (or per EARLY_FLUSH_BYTES of a long one) into one frame per
topic, large ones alone and copied once, nothing encoded while nobody subscribes, every queue
bounded and what overflows counted, frames held back (within a bound) for keep-all consumers
of this host until they return credits (transport.events.credits).
The overview is transport.events; the bytes are transport.events.frames.
"""

from __future__ import annotations

import functools
import itertools
import random
import threading
import time
from typing import Any

from miro_gen import clock
from miro_gen.log import logger
from miro_gen.runtime.cdr import Encoder, encode_after
from miro_gen.transport import shm, sockets
from miro_gen.transport.events import credits, offers
from miro_gen.transport.events.channels import PROXY_HWM, EventChannel
from miro_gen.transport.events.frames import (
    BATCH_HEADER,
    EVENT,
    EVENT_HEADER,
    LENGTH,
    LENGTH_AT,
    SHM,
    batch_head,
    split_topic,
    topic,
)
from miro_gen.transport.events.links import PublishingLink

_log = logger("MIRO")

HWM = 10_000  # frames a supplier's or a consumer's socket queues for one peer, at most
MAX_SUBSCRIPTIONS = 10_000  # prefixes a supplier tracks; beyond, it sends every topic
MAX_PREFIX = 4096  # bytes of a subscription prefix a supplier tracks
QUEUE_EVENTS = 100_000  # events a supplier holds for its reactor's next turn, at most
QUEUE_BYTES = 64 << 20  # and bytes
# Events from this size on travel alone, in a frame put together with one copy and handed to
# ZeroMQ without another (copy=False); consumers decode them from ZeroMQ's buffer, in place.
# Between processes of one host they take shared memory: transport.shm owns the size.
LARGE_EVENT = shm.THRESHOLD
# Events in one frame, at most. The count is 16 bits, and a high-water mark counts frames: HWM
# frames must stay a bounded amount of memory. Yet frames must not be small: each send lets the
# pushing thread take the GIL back for up to a switch interval, so a flush in many frames falls
# behind a thread pushing flat out. An event larger than MAX_BATCH_BYTES travels alone.
MAX_BATCH_EVENTS = 16_384
MAX_BATCH_BYTES = 256 * 1024
# Pushes on the reactor thread send what waits once it reaches this many bytes, rather than at
# the end of the reactor's turn: a long turn (a timer or a handler pushing thousands of events)
# otherwise encodes them all before the first leaves, and the link, the network, the router
# and the consumers wait for it, then it for them. Sent early, their work overlaps its own;
# on a loaded machine (every thread waits for a core) that overlap is most of the throughput.
EARLY_FLUSH_BYTES = 32 * 1024
RETRY = 0.001  # seconds before a flush held back by keep-all consumers' credits tries again


class _Framed(list[bytes]):
    """A large event's whole batch frame: it travels alone (a second item: its own topic
    frame, a descriptor's)."""


class _Topic:
    """What a supplier keeps per type name: the topic frame, the sequence numbers, whether
    anyone subscribes (recomputed when the subscriptions change), the events not yet sent,
    whether the last event was large, whether its large events go through shared memory (all its
    subscribers are on this host: transport.shm) and the ring they go through."""

    __slots__ = (
        "credits",
        "frame",
        "generation",
        "keep_all",
        "large",
        "last",
        "last_hash",
        "pending",
        "ring",
        "seq",
        "shared",
        "shm_frame",
        "subscribed",
    )

    def __init__(self, frame: bytes, marker: bytes) -> None:
        self.frame = frame
        # Keep-all consumers of this host that return credits (transport.events.credits), and
        # the frames in flight toward them.
        self.credits: credits.TopicCredits | None = None
        self.shm_frame = marker + frame
        self.shared = False
        self.keep_all = 0  # keep-all consumers of this host (transport.shm)
        self.ring: shm.Ring | None = None
        self.large = False
        self.seq = itertools.count()
        self.generation = -1  # of the supplier's subscriptions that `subscribed` reflects
        self.subscribed = False
        # Runs of packed events with one type hash (one, unless the type changes), the last
        # run's list and hash.
        self.pending: list[tuple[str, list[bytes]]] = []
        self.last: list[bytes] = []
        self.last_hash = ""


class StructuredPushSupplier:
    """Pushes events into a channel. `push()` may be called from any thread; the sending
    happens on the reactor thread, once per turn for all events pushed meanwhile (and, for
    pushes on the reactor thread, whenever EARLY_FLUSH_BYTES wait).

    Events wait for that turn in a bounded queue (QUEUE_EVENTS events, QUEUE_BYTES bytes): when
    the reactor cannot keep up, `push()` drops the newest and counts them in `dropped`, as it
    does those ZeroMQ refuses at its high-water mark, those larger than the maximum message
    size, and those pushed for subscribers while the channel is gone (its host died; the
    supplier finds it again when it is bound anew). Consumers see them as gaps.

    Keep-all consumers of this host return credits (transport.events.credits): a topic's
    frames go toward them only while each has fewer than `window` in flight; the rest wait in
    the queue, at most shm.WAIT_KEEP_ALL seconds of blocked sending per consumer, and a `push()`
    off the reactor thread that finds the queue full waits as long for room before it drops
    (`waited` counts those that waited).

    `direct`: a link that sends on the caller's thread (transport.events.links), for a
    subclass that sends a frame at once (`_send_frame` from any thread: the log player's
    replay, eventlog.replay); `push()` still waits for the reactor's turn."""

    def __init__(
        self, channel: EventChannel, domain_name: str | None = None, *, direct: bool = False
    ) -> None:
        self.channel = channel
        self.domain_name = channel.domain_name if domain_name is None else domain_name
        self.reactor = channel.reactor
        self.supplier_id = random.getrandbits(63)
        self._topics: dict[str, _Topic] = {}
        self._dirty: list[_Topic] = []  # topics with pending events, in the order they came
        self._queued = 0
        self._queued_bytes = 0
        self._lock = threading.Lock()
        self._flush_pending = False
        self._subscriptions: dict[bytes, int] = {}
        self._generation = 0  # bumped whenever _subscriptions changes
        self._raw_hashes: dict[str, bytes] = {}
        self._offered: dict[str, str] = {}  # type name -> payload type hash, as described
        self.sent = 0
        self.dropped = 0  # events pushed while someone subscribed that were never sent
        self._too_large: set[str] = set()  # types with an event too large to send (said once)
        self.max_frame = sockets.policy(self.reactor.context).max_message_size
        self._connected = False
        self._lost: set[bytes] = set()  # the subscriptions when the channel went away
        # Large events through shared memory to consumers of this host (transport.shm):
        # not over a backbone without channel hosts, nor where the platform has no memfd.
        self._marker = shm.topic_marker() if shm.enabled() and channel.links is None else b""
        self._keep_all_marker = shm.keep_all_marker()
        self._rings_lock = threading.Lock()
        # Keep-all consumers of this host return credits for every event (transport.events
        # .credits): at most `window` frames of a topic in flight toward each, half what the
        # channel queues for it (libzmq credits its reader every half high-water mark).
        self._keep_all = credits.KeepAllConsumers(credits.credit_marker() if self._marker else b"")
        self.window = max(2, min(PROXY_HWM, sockets.queue_limit(self.reactor.context)) // 2)
        self._retry: int | None = None
        self.waited = 0  # pushes that waited for room, held back by keep-all consumers
        self._waited_out = False  # a push waited the bound in vain: none waits until room is made
        # A turn's events leave in a burst of frames (100,000 small events: about 140, sent as
        # they fill EARLY_FLUSH_BYTES), which the link must hold until the channel reads them
        # (on this very reactor, when this process hosts the channel): room for a full queue
        # of them (QUEUE_BYTES), more only when the supplier's own events are larger.
        burst = QUEUE_BYTES // EARLY_FLUSH_BYTES
        self.link: PublishingLink = channel.publishing(
            self._connection_changed, self._subscriptions_changed, HWM, burst, direct=direct
        )
        if direct and channel.links is None:  # sends may come before the reactor's turn
            self._connected = self.link.connected  # says so (in-process: up at once)

    def _topic(self, type_name: str) -> _Topic:
        t = self._topics.get(type_name)
        if t is None:  # setdefault: two threads creating it at once share one counter
            frame = topic(self.domain_name, type_name)
            t = self._topics.setdefault(type_name, _Topic(frame, self._marker))
        return t

    def _subscribed(self, t: _Topic) -> bool:
        generation = self._generation
        if t.generation != generation:
            subs = list(self._subscriptions.items())
            # Which prefixes are subscribed, not by how many (shm.framed_marker says why).
            # Consumers of this host subscribe to each prefix twice, plainly and after its
            # marker; those of other hosts after theirs, and those that need frames after
            # framed_marker. Large events take shared memory when every plain prefix has its
            # twin after this host's marker and no subscriber of the topic needs frames.
            plain = {p for p, _ in subs if t.frame.startswith(p)}
            mine: set[bytes] = set()
            framed = False
            for p, _ in subs:
                found = shm.marked(p)
                if found is not None and t.frame.startswith(found[1]):
                    if self._marker and found[0] == self._marker:
                        mine.add(found[1])
                    else:
                        framed = True
            t.subscribed = bool(plain or mine)
            t.shared = bool(mine) and plain <= mine and not framed
            if t.shared:
                marker = self._keep_all_marker
                keep_all = marker + t.frame
                t.keep_all = sum(
                    n for p, n in subs if p.startswith(marker) and keep_all.startswith(p)
                )
            if self._keep_all.marker:
                if t.credits is None:
                    type_name = split_topic(t.frame)[1]
                    t.credits = credits.TopicCredits(t.frame, type_name, self.window)
                if t.credits.update(self._keep_all, generation):  # one more or fewer credited
                    credits.share_window(
                        (u.credits for u in self._topics.values() if u.credits), self.window
                    )
            t.generation = generation  # a change meanwhile bumped _generation: recomputed next
        return t.subscribed

    def has_subscribers(self, type_name: str) -> bool:
        """Whether any consumer subscribes to this supplier's events of `type_name`."""
        return self._subscribed(self._topic(type_name))

    def subscriptions(self, type_name: str) -> int:
        """How many subscriptions (of consumers, through the channel) match this supplier's
        events of `type_name`; on the reactor thread (`miro pub --wait-matching`)."""
        frame = self._topic(type_name).frame
        return sum(n for prefix, n in self._subscriptions.items() if frame.startswith(prefix))

    def push(self, type_name: str, payload: Any, stamp: float | None = None) -> bool:
        """Publish `payload` (a generated type) as an event of `type_name`; False when nobody
        subscribes (nothing is encoded then). `stamp`: when the data was taken (default now, on the
        process's clock: the replayed time under `--clock log`)."""
        t = self._topics.get(type_name) or self._topic(type_name)
        offered = getattr(payload, "_type_hash", "")
        if self._offered.get(type_name) != offered:  # the first of its kind
            self._offered[type_name] = offered
            offers.offered(self.channel.name, self.domain_name, type_name, payload)
        seq = next(t.seq)
        if not (t.subscribed if t.generation == self._generation else self._subscribed(t)):
            if not self._connected and any(t.frame.startswith(p) for p in self._lost):
                with self._lock:  # subscribed when the channel went away: lost
                    self.dropped += 1
                return True
            return False
        now = clock.current().time_ns()  # log time under --clock log, else the wall clock
        type_hash = offered or payload._type_hash
        stamp_ns = now if stamp is None else int(stamp * 1e9)
        shared = None
        if t.shared:
            packed, framed, shared = self._encode_shared(
                t, type_hash, (seq, stamp_ns, now), payload
            )
            if not (packed or framed):  # no slot in time
                with self._lock:
                    self.dropped += 1
                return True
        elif t.large:
            packed, framed = self._encode_large(t, type_hash, (seq, stamp_ns, now), payload)
        else:  # the common case, inline: a small event's header and CDR, to be batched
            data = payload.serialize()
            n = len(data)
            if n + EVENT_HEADER < LARGE_EVENT:
                packed, framed = EVENT.pack(seq, stamp_ns, now, n) + data, b""
            else:  # the first large one of its type: alone, and the next encoded in place
                t.large = True
                head = EVENT.pack(seq, stamp_ns, now, n)
                packed, framed = b"", b"".join((self._batch_head(type_hash, 1), head, data))
        size = len(framed or packed)
        if shared is None and (size if framed else size + BATCH_HEADER) > self.max_frame:
            self._refuse_large(type_name, size)
            return True
        full = self._queued >= QUEUE_EVENTS or self._queued_bytes + size > QUEUE_BYTES
        if full and t.credits and t.credits.readers and not self._waited_out:
            self._wait_for_room(size)
        with self._lock:
            if self._queued >= QUEUE_EVENTS or self._queued_bytes + size > QUEUE_BYTES:
                self.dropped += 1
                return True
            if framed:  # alone, as it is
                if not t.pending:
                    self._dirty.append(t)
                alone = _Framed((framed,) if shared is None else (framed, t.shm_frame))
                t.pending.append((type_hash, alone))
                t.last, t.last_hash = [], ""
            elif type_hash == t.last_hash and t.pending:
                t.last.append(packed)
            else:
                if not t.pending:
                    self._dirty.append(t)
                t.last, t.last_hash = [packed], type_hash
                t.pending.append((type_hash, t.last))
            self._queued += 1
            self._queued_bytes += size
            early = self._queued_bytes >= EARLY_FLUSH_BYTES
            if self._flush_pending and not early:
                return True
            scheduled, self._flush_pending = self._flush_pending, True
        if early and self._retry is None and self.reactor.in_reactor_thread():
            self._flush()  # a long turn of pushes: send what it has so far (see EARLY_FLUSH_BYTES)
        elif not scheduled:
            self.reactor.call_soon(self._flush)
        return True

    def _encode_large(
        self, t: _Topic, type_hash: str, head: tuple[int, int, int], payload: Any
    ) -> tuple[bytes, bytes]:
        """(b"", its whole frame) for an event of a type whose last event was large: encoded
        into its frame directly (its payload copied once), the payload length filled in after;
        (event, b"") when it turns out small, to be batched (and the next encoded as usual)."""
        prefix = self._batch_head(type_hash, 1) + EVENT.pack(*head, 0)
        buf = encode_after(prefix, payload)
        n = buf.size - len(prefix)
        buf.overwrite(LENGTH_AT, LENGTH.pack(n))
        frame = buf.value()
        if n + EVENT_HEADER >= LARGE_EVENT:
            return b"", frame
        t.large = False
        return frame[BATCH_HEADER:], b""

    def _encode_shared(
        self, t: _Topic, type_hash: str, head: tuple[int, int, int], payload: Any
    ) -> tuple[bytes, bytes, shm.Descriptor | None]:
        """As `_encode_large` and the inline case, for a topic whose consumers are all on this
        host: a large event's payload goes into the topic's ring, its frame carries the
        descriptor. (b"", b"", None) when no slot frees up in time (dropped: keep-all consumers
        behind, or all held)."""
        encoded: bytes | Encoder
        if t.large:  # after a large one: encoded straight into the slot (its data set aside)
            encoded = encode_after(b"", payload)
            size = encoded.size
            if size + EVENT_HEADER < LARGE_EVENT:
                t.large = False
                data = encoded.value()
                return EVENT.pack(*head, len(data)) + data, b"", None
        else:
            encoded = payload.serialize()
            size = len(encoded)
            if size + EVENT_HEADER < LARGE_EVENT:
                return EVENT.pack(*head, size) + encoded, b"", None
            t.large = True
        ring = t.ring
        if ring is None:
            with self._rings_lock:
                ring = t.ring
                if ring is None:
                    ring = t.ring = shm.Ring(self.max_frame)
        if size > ring.slot_size:  # larger than any message: framed as over the network, so
            # that push refuses it as such (its size is over max_frame)
            whole = encoded if isinstance(encoded, bytes) else encoded.value()
            event_head = EVENT.pack(*head, size)
            return b"", b"".join((self._batch_head(type_hash, 1), event_head, whole)), None
        # The encoder copies into the slot. On the reactor thread a push does not wait for
        # credits: a keep-all consumer of this process could not return them meanwhile.
        wait = 0.0 if self.reactor.in_reactor_thread() else shm.WAIT_KEEP_ALL
        d = ring.put(encoded, functools.partial(self._keep_all_lanes, t) if t.keep_all else 0, wait)
        if d is None:
            return b"", b"", None
        frame = b"".join(
            (
                self._batch_head(type_hash, 1, SHM),
                EVENT.pack(*head, shm.DESCRIPTOR.size),
                shm.DESCRIPTOR.pack(*d),
            )
        )
        return b"", frame, d

    def _keep_all_lanes(self, t: _Topic) -> int:
        """The keep-all consumers whose lanes `t`'s ring waits for, as the subscriptions are
        now (a put that waits asks again: a consumer killed meanwhile is not waited for)."""
        self._subscribed(t)
        return self._keep_all.lanes(t.frame, t.keep_all) if self._keep_all.marker else t.keep_all

    def _batch_head(self, type_hash: str, count: int, flags: int = 0) -> bytes:
        raw = self._raw_hashes.get(type_hash)
        if raw is None:
            raw = self._raw_hashes[type_hash] = bytes.fromhex(type_hash)
        return batch_head(count, self.supplier_id, raw, flags)

    def _wait_for_room(self, size: int) -> None:
        """Backpressure from keep-all consumers: wait, off the reactor thread, at most
        shm.WAIT_KEEP_ALL seconds for the queue to take an event of `size` bytes."""
        if self.reactor.in_reactor_thread():
            return  # a keep-all consumer of this very process could not read meanwhile
        self.waited += 1
        deadline = time.monotonic() + shm.WAIT_KEEP_ALL
        pause = 0.0002
        while self._queued >= QUEUE_EVENTS or self._queued_bytes + size > QUEUE_BYTES:
            if time.monotonic() >= deadline or self.reactor.closed:
                self._waited_out = True
                return
            time.sleep(pause)
            pause = min(pause * 2, 0.005)

    def _flush(self) -> None:
        with self._lock:
            topics, self._dirty = self._dirty, []
            queues = []
            for t in topics:
                queues.append((t, t.pending))
                t.pending, t.last, t.last_hash = [], [], ""
            queued = [self._queued, self._queued_bytes]  # less what is sent: what is held back
            before = self._queued
            self._queued = self._queued_bytes = 0
            self._flush_pending = False
        held: list[tuple[_Topic, list[tuple[str, list[bytes]]]]] = []
        for t, runs in queues:
            rest = self._send_runs(t, runs, queued)
            if rest:
                held.append((t, rest))
        if queued[0] < before:
            self._waited_out = False  # room made: pushes may wait again
        if held:
            self._hold_back(held, queued[0], queued[1])

    def _send_runs(
        self, t: _Topic, runs: list[tuple[str, list[bytes]]], queued: list[int]
    ) -> list[Any]:
        """Send a topic's runs of events, in frames within the limits; what its keep-all
        consumers' credits hold back (transport.events.credits), from the first frame not sent.
        `queued`: (events, bytes) counted down by what is sent."""
        flow = t.credits.flow if t.credits and t.credits.readers else None
        if flow is not None and not self._room(t):
            return runs  # (a retry costs nothing while the credits have not come)
        frame = t.frame
        for i, (type_hash, events) in enumerate(runs):
            if type(events) is _Framed:
                if flow is not None and i and not self._room(t):
                    return runs[i:]
                self._send_body(events[-1] if len(events) > 1 else frame, events[0], 1)
                if flow is not None:
                    flow.sending(EVENT.unpack_from(events[0], BATCH_HEADER)[0])
                queued[0] -= 1
                queued[1] -= len(events[0])
                continue
            total = sum(map(len, events))
            if len(events) <= MAX_BATCH_EVENTS and total <= MAX_BATCH_BYTES:
                if flow is not None:
                    if i and not self._room(t):
                        return runs[i:]
                    flow.sending(EVENT.unpack_from(events[-1])[0])
                queued[0] -= len(events)
                queued[1] -= total
                self._send(frame, type_hash, events)
                continue
            start, size = 0, 0
            for j, packed in enumerate(events):  # a busy turn: several frames, within the limits
                if j > start and (
                    j - start == MAX_BATCH_EVENTS or size + len(packed) > MAX_BATCH_BYTES
                ):
                    if flow is not None:
                        if (i or start) and not self._room(t):
                            return [(type_hash, events[start:]), *runs[i + 1 :]]
                        flow.sending(EVENT.unpack_from(events[j - 1])[0])
                    queued[0] -= j - start
                    queued[1] -= size
                    self._send(frame, type_hash, events[start:j])
                    start, size = j, 0
                size += len(packed)
            if flow is not None:
                if (i or start) and not self._room(t):
                    return [(type_hash, events[start:]), *runs[i + 1 :]]
                flow.sending(EVENT.unpack_from(events[-1])[0])
            queued[0] -= len(events) - start
            queued[1] -= size
            self._send(frame, type_hash, events[start:])
        return []

    def _room(self, t: _Topic) -> bool:
        return t.credits is None or t.credits.room(self.supplier_id)

    def _hold_back(self, held: list[tuple[_Topic, list[Any]]], events: int, size: int) -> None:
        """Put `events` (`size` bytes) whose frames credits held back in front of those pushed
        since, and try again shortly (reactor thread)."""
        with self._lock:
            self._queued += events
            self._queued_bytes += size
            for t, rest in held:
                if t.pending:  # (it is in _dirty already)
                    t.pending[:0] = rest
                    continue
                t.pending = rest
                self._dirty.append(t)
                last_hash, last = rest[-1]
                if type(last) is not _Framed:  # later pushes join its last frame
                    t.last, t.last_hash = last, last_hash
        # Tried again after RETRY on the reactor's clock, and by the next push's flush (which
        # `_flush_pending` still lets it schedule: a log clock may be paused).
        if self._retry is None:
            self._retry = self.reactor.schedule_timer(RETRY, 0, self._retried)

    def _retried(self, _: object) -> None:
        self._retry = None
        self._flush()

    def _send(self, frame: bytes, type_hash: str, packed: list[bytes]) -> None:
        """One frame of the events `packed`."""
        body = b"".join([self._batch_head(type_hash, len(packed)), *packed])
        self._send_body(frame, body, len(packed))

    def _send_body(self, frame: bytes, body: bytes, count: int) -> None:
        if self._send_frame(frame, body):
            self.sent += count
        else:  # at the high-water mark: dropped, visible as a gap
            with self._lock:
                self.dropped += count

    def _send_frame(self, frame: bytes, body: bytes) -> bool:
        """Send a topic frame and a batch frame (large ones without a copy); False at the
        high-water mark, or when the channel is gone (nobody to send to: the events are lost)."""
        if not self._connected:
            return False
        return self.link.send(frame, body, len(body) < LARGE_EVENT)

    def _refuse_large(self, type_name: str, size: int) -> None:
        with self._lock:
            self.dropped += 1
        if type_name not in self._too_large and len(self._too_large) < 1000:
            self._too_large.add(type_name)
            _log.warning(
                "dropped a %s event of %d bytes: more than the maximum message size "
                "(%d; --max-message-size)",
                type_name,
                size,
                self.max_frame,
            )

    def _connection_changed(self, up: bool) -> None:
        """The connection to the channel came up or went down (reactor thread)."""
        if up:
            self._lost = set()
        else:
            self._lost = set(self._subscriptions)
            _log.notice("lost the event channel %s; looking for it", self.channel.name)
        self._connected = up

    def _subscriptions_changed(self, changes: list[tuple[bool, bytes]]) -> None:
        """Consumers (un)subscribed, as the link heard it (reactor thread): after a lost
        connection's notice, so that `_lost` still holds what it ended."""
        subs = self._subscriptions
        for subscribed, whole in changes:
            if self._keep_all.marker and self._keep_all.change(subscribed, whole):
                continue  # a keep-all consumer's credits (transport.events.credits)
            prefix = whole[:MAX_PREFIX]  # a longer prefix matches no fewer topics
            if prefix not in subs and len(subs) >= MAX_SUBSCRIPTIONS:
                prefix = b""  # too many to track: send every topic (the channel filters)
            n = subs.get(prefix, 0) + (1 if subscribed else -1)
            if n > 0:
                subs[prefix] = n
            else:
                subs.pop(prefix, None)
        self._generation += 1  # after the change, so a reader never keeps a stale answer

    def close(self) -> None:
        self.link.close()
        if self._retry is not None:
            self.reactor.cancel_timer(self._retry)
        self.reactor.call_soon(self._keep_all.close)
        for t in list(self._topics.values()):
            if t.ring is not None:
                t.ring.close()
