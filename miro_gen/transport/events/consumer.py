"""Consumers of an event channel (Miro's StructuredPushConsumer): subscriptions by (domain,
type), frames parsed on the reactor thread, payloads decoded with the generated class their
type hash names (runtime.registry) when the handler is ready for them, as the consumer's
quality of service keeps them (transport.events.queue), gaps counted per supplier and type.
The overview is transport.events; the bytes are transport.events.frames.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from struct import error as StructError

from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime import registry
from miro_gen.runtime.datatypes import IdlType
from miro_gen.runtime.views import octet_views
from miro_gen.transport import shm
from miro_gen.transport.events import credits, offers
from miro_gen.transport.events.channels import EventChannel
from miro_gen.transport.events.event import StructuredEvent
from miro_gen.transport.events.frames import (
    BATCH_HEADER,
    EVENT,
    EVENT_HEADER,
    SHM,
    batch_flags,
    next_due,
    read_batch_head,
    split_topic,
    topic,
)
from miro_gen.transport.events.gaps import GapCounter, gap
from miro_gen.transport.events.links import SubscribingLink
from miro_gen.transport.events.queue import DEFAULT_DEPTH, KEEP_ALL, EventQueue, Waiting
from miro_gen.transport.events.supplier import HWM, LARGE_EVENT

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

TURN_EVENTS = 4096  # events a consumer delivers per reactor turn, so other handlers get a turn
TURN_FRAMES = 256  # frames a consumer reads per reactor turn
# Frames of a type hash no imported type has wait, at most this many and bytes, while the
# generated packages on the path are imported (in a thread: runtime.registry.discover).
HOLD_FRAMES = 1000
HOLD_BYTES = 64 << 20
SWEEP_EVERY = 1.0  # seconds between looks for mappings of suppliers that have died
ANY = "*"


def subscription_prefix(domain: str, type_name: str) -> bytes:
    """What to subscribe to at the socket for (domain, type); `*` matches any. A `*` domain
    with a named type cannot be a prefix: it subscribes to all, and the consumer filters."""
    if domain == ANY:
        return b""
    if type_name == ANY:
        return domain.encode() + b"\0"
    return topic(domain, type_name)


class StructuredPushConsumer:
    """Receives the events it subscribes to. Subclass it and override
    `push_structured_event(event)`; it runs on the reactor thread, so it must not block.

    Events wait for the handler in a queue kept as `depth` says (transport.events.queue): the
    newest 10 per topic by default, as ROS 2 keeps them; `latest_only` keeps the newest one;
    `depth=KEEP_ALL` keeps everything up to the queue's byte limit. `missed` counts events lost
    on the way (sequence gaps; for a keep-all consumer also those beyond its queue's byte
    limit), `dropped` those this consumer skipped because its handler fell behind, `lag` how
    old (seconds since it was pushed) the last event delivered was.

    A keep-all consumer on the host of its suppliers returns credits for every event it takes
    off its socket (transport.events.credits), so that they never send more than the channel
    queues for it: nothing is lost on the way while it reads at least every shm.WAIT_KEEP_ALL
    seconds.

    Large events from suppliers on this host arrive through shared memory (transport.shm)
    and are decoded from it: the payload is the same as over the network. With `zero_copy`,
    their sequences of octets (image data) are not copied but read-only memoryviews of the
    shared slot instead (`numpy.frombuffer` makes a read-only array of one): valid only while
    `push_structured_event` runs, after which the slot may be written again; copy what must
    outlive the handler."""

    def __init__(
        self,
        channel: EventChannel,
        *,
        depth: int = DEFAULT_DEPTH,
        latest_only: bool = False,
        zero_copy: bool = False,
    ) -> None:
        self.channel = channel
        self.reactor = channel.reactor
        self.queue = EventQueue(depth, latest_only)
        self.zero_copy = zero_copy
        self._keep_all = depth == KEEP_ALL and not latest_only
        self._marker = shm.topic_marker() if shm.enabled() and channel.links is None else b""
        self._segments = shm.Segments(self._keep_all)
        # A keep-all consumer returns credits for every event to suppliers of its host
        # (transport.events.credits), so that they never have more in flight than the
        # channel's queue for it holds.
        self._credits: credits.CreditTable | None = None
        if self._keep_all and self._marker and credits.credit_marker():
            try:
                self._credits = credits.CreditTable()
            except OSError as e:
                _log.warning("keep-all consumer without credits (no memfd): %s", e)
        self._sweeper: int | None = None
        self.torn = 0  # shared-memory events rewritten while read (dropped, counted in dropped)
        self._filters: list[tuple[str, str]] = []
        self._prefixes: set[bytes] = set()
        self._gaps = GapCounter()  # per (supplier, type name), bounded
        self._topics: dict[bytes, tuple[str, str, bool]] = {}
        self._classes: dict[bytes, type[IdlType]] = {}
        self._unknown: set[tuple[str, str]] = set()
        self._held: list[tuple[bytes, memoryview]] = []  # frames waiting for their types
        self._held_hashes: set[bytes] = set()
        self._held_bytes = 0
        self._searching = False
        self._scheduled = False
        self.received = 0
        self.undecodable = 0  # events whose type hash matches no imported generated type
        self.lag = 0.0  # seconds between the push and the delivery of the last event delivered
        self.link: SubscribingLink = channel.subscribing(
            self._readable, HWM, keep_all=self._keep_all
        )

    @property
    def missed(self) -> int:
        """Events lost between their suppliers and this consumer (sequence gaps); for a
        keep-all consumer also those its queue could not hold (its byte bound): it keeps all."""
        return self._gaps.missed + (self.queue.overflowed if self._keep_all else 0)

    @property
    def dropped(self) -> int:
        """Events received but skipped: the handler fell behind (depth, latest-only), or, from
        shared memory, a keep-last consumer lapped or a payload torn."""
        return self.queue.dropped - (self.queue.overflowed if self._keep_all else 0)

    def set_subscriptions(self, subscriptions: Iterable[tuple[str, str]]) -> None:
        """Receive the events of these (domain, type) pairs, `*` for any; replaces the last."""
        subs = [(d, t) for d, t in subscriptions]
        prefixes = {subscription_prefix(d, t) for d, t in subs}
        offers.subscribed(self, self.channel.name, subs)

        marker = self._marker
        # Large events from this host come through shared memory (its marker); a keep-all
        # consumer says so, so that suppliers wait for it (a prefix no frame starts with).
        # Without shared memory, on a channel host, it says it needs them in frames.
        markers = [marker] if marker else []
        if marker and self._keep_all:
            markers.append(shm.keep_all_marker())
        if not marker and self.channel.links is None:
            markers.append(shm.framed_marker())
        table, credit_marker = self._credits, credits.credit_marker()

        def apply() -> None:
            for p in self._prefixes - prefixes:
                self.link.unsubscribe(p)
                for m in markers:
                    self.link.unsubscribe(m + p)
                if table is not None:
                    self.link.unsubscribe(table.subscription(credit_marker, p))
            for p in prefixes - self._prefixes:
                self.link.subscribe(p)
                for m in markers:
                    self.link.subscribe(m + p)
                if table is not None:  # last: suppliers take the topic's subscriptions first
                    self.link.subscribe(table.subscription(credit_marker, p))
            self._segments.close()  # lanes only in the rings of what it still subscribes to
            self._prefixes = prefixes
            self._filters = subs
            self._topics.clear()

        self.reactor.call_soon(apply)

    def push_structured_event(self, event: StructuredEvent) -> None:
        """Called for each event received (override it)."""

    def _wanted(self, domain: str, type_name: str) -> bool:
        return any((d in (ANY, domain)) and (t in (ANY, type_name)) for d, t in self._filters)

    def _readable(self) -> None:
        """Take every frame waiting (so that the queue, not ZeroMQ, decides what waits), then
        deliver a turn's worth of events."""
        receive, queue = self.link.receive, self.queue
        for _ in range(TURN_FRAMES):
            try:
                frame = receive()  # (the batch not copied: large payloads decode in place)
                if frame is None:
                    break
                self._parse(*frame)
            except (ValueError, StructError, UnicodeDecodeError) as e:
                _peer_warnings.warning("dropped an event frame on %s: %s", self.channel.name, e)
        else:
            self._schedule()  # more frames may wait: read them next turn
        if len(queue):
            self._deliver()

    def _schedule(self) -> None:
        if not self._scheduled:
            self._scheduled = True
            self.reactor.call_soon(self._resume)

    def _resume(self) -> None:
        self._scheduled = False
        self._readable()

    def _deliver(self) -> None:
        deliver, queue, reactor = self.push_structured_event, self.queue, self.reactor
        taken = queue.take(TURN_EVENTS)  # a turn's worth at once, not one call per event
        # Newest first, each popped as it is delivered: the turn keeps no delivered event (and
        # so no decoded payload) alive until its end, as a loop over `taken` would; with large
        # payloads those are megabytes each, freed all at once and faulted in again next turn.
        taken.reverse()
        pop = taken.pop
        n = 0
        while taken:
            if reactor.stopping:
                taken.reverse()
                queue.put_back(taken)
                break
            _, event, cls, _ = pop()
            shared = event.payload if type(event.payload) is _Shared else None
            if shared is not None:
                if not self._decode_shared(event, cls, shared):
                    continue
            else:
                try:
                    event.payload = cls.deserialize(event.payload)
                except Exception as e:  # MARSHAL: a corrupt payload is reported, not delivered
                    _peer_warnings.warning(
                        "dropped an undecodable %s event: %s", event.type_name, e
                    )
                    continue
            n += 1
            self.lag = time.time() - event.publish_time
            try:
                deliver(event)
            except Exception:
                _log.exception("push_structured_event failed on %s", event.type_name)
            if shared is not None:
                shared.segment.release(shared.descriptor, self._keep_all)
        self.received += n
        if len(queue) and not reactor.stopping:
            self._schedule()  # the rest next turn: other handlers get theirs meanwhile

    def _decode_shared(self, event: StructuredEvent, cls: type[IdlType], shared: _Shared) -> bool:
        """Decode an event from its slot, which it then holds until released; False (the
        event dropped and counted) when the slot was written again before or during the read."""
        seg, d = shared.segment, shared.descriptor
        view = seg.hold(d)
        if view is None:  # lapped: a keep-last consumer a ring behind
            self.queue.dropped += 1
            return False
        try:
            if self.zero_copy:
                with octet_views():
                    event.payload = cls.deserialize(view)
            else:
                event.payload = cls.deserialize(view)
        except Exception as e:
            seg.release(d, self._keep_all)
            if seg.current(d):
                _peer_warnings.warning("dropped an undecodable %s event: %s", event.type_name, e)
            else:
                self.torn += 1
                self.queue.dropped += 1
            return False
        if not seg.current(d):  # rewritten while read: torn
            seg.release(d, self._keep_all)
            self.torn += 1
            self.queue.dropped += 1
            return False
        return True

    def _shared(self, d: shm.Descriptor) -> _Shared | None:
        """The mapping of a descriptor's segment (mapped on first use), None if it cannot be."""
        seg = self._segments.segment(d)
        if seg is None or not seg.valid(d):
            return None
        if self._sweeper is None:  # unmap the segments of suppliers that die
            self._sweeper = self.reactor.schedule_timer(
                SWEEP_EVERY, SWEEP_EVERY, lambda _: self._segments.sweep()
            )
        return _Shared(seg, d)

    def _topic(self, head: bytes) -> tuple[str, str, bool]:
        """(domain, type name, whether subscribed) of a topic frame."""
        known = self._topics.get(head)
        if known is None:
            if head[:1] == b"\x01":  # shared memory: ours, or another host's (not for us)
                marker = self._marker
                if not marker or not head.startswith(marker):
                    return "", "", False
                head = head[len(marker) :]
            domain, type_name = split_topic(head)
            known = (domain, type_name, self._wanted(domain, type_name))
            if len(self._topics) >= 4096:  # a bounded cache, whatever the channel carries
                self._topics.clear()
            self._topics[head] = known
        return known

    def _class(self, raw_hash: bytes, domain: str, type_name: str) -> type[IdlType] | None:
        """The generated type of payloads with this type hash; None (reported once) if none."""
        cls = self._classes.get(raw_hash)
        if cls is None:
            type_hash = raw_hash.hex()
            cls = registry.lookup(type_hash)  # never searches the path: this is the reactor
            if cls is not None:
                self._classes[raw_hash] = cls
            elif self._searching or not registry.discovered():
                pass  # its frames wait for the search (_hold)
            elif (type_name, type_hash) not in self._unknown and len(self._unknown) < 1000:
                self._unknown.add((type_name, type_hash))
                _peer_warnings.warning(
                    "events %s/%s have type hash %s, which no imported generated type has: "
                    "dropped (import the type's generated module, or regenerate it)",
                    domain,
                    type_name,
                    type_hash[:12],
                )
        return cls

    def _parse(self, head: bytes, body: memoryview) -> None:
        """Queue the events of one message (its topic, its batch); raises if the batch does not
        parse (then none of its events count, and the sequence numbers stay as they were)."""
        domain, type_name, wanted = self._topic(head)
        if not wanted:
            if self._credits is not None and type_name:  # subscribed to all, filtered here
                self._credit_frame(body, type_name)
            return
        count, supplier, raw_hash = read_batch_head(body)
        held = self._held and raw_hash in self._held_hashes  # after those already waiting
        cls = None if held else self._class(raw_hash, domain, type_name)
        if cls is None and self._hold((head, body), raw_hash, len(body)):
            if self._credits is not None:  # it waits here, off the channel's queue
                self._credit_frame(body, type_name)
            return
        if held:
            cls = self._class(raw_hash, domain, type_name)
        shared = batch_flags(body) & SHM
        if shared and count != 1:
            raise ValueError("a shared-memory frame has one descriptor")
        type_hash = raw_hash.hex()
        expected = self._gaps.expected(supplier, type_name)
        first = expected
        missed = 0
        unpack, size, at = EVENT.unpack_from, len(body), BATCH_HEADER
        # Small payloads are copied out (so that a batch's frame is not kept for one event that
        # waits): in one step from the bytes under the view when there are such.
        whole = body.obj if type(body.obj) is bytes and len(body.obj) == size else body
        topic_key = (domain, type_name)
        waiting: list[Waiting] = []
        total = 0
        keep_from = count - 1 if self.queue.latest_only else 0  # latest-only: only the last
        for i in range(count):
            seq, stamp_ns, publish_ns, n = unpack(body, at)
            at += EVENT_HEADER
            if at + n > size:
                raise ValueError("event payload is truncated")
            if seq != expected:
                missed += gap(expected, seq)
            expected = seq + 1
            if cls is not None and i >= keep_from:
                # Decoded when delivered; a small payload is copied out, so that a batch's
                # frame is not kept for one event that waits.
                data: object
                if shared:
                    if n != shm.DESCRIPTOR.size:
                        raise ValueError("malformed shared-memory descriptor")
                    d = shm.Descriptor(*shm.DESCRIPTOR.unpack_from(body, at))
                    data = self._shared(d)
                    if data is None:  # not mappable here: lost on the way
                        missed += 1
                        at += n
                        continue
                    held = n  # the payload is in the supplier's pool, which bounds it
                else:
                    data = body[at : at + n] if n >= LARGE_EVENT else bytes(whole[at : at + n])
                    held = n
                event = StructuredEvent(
                    domain,
                    type_name,
                    data,
                    seq,
                    stamp_ns / 1e9,
                    publish_ns / 1e9,
                    supplier,
                    type_hash,
                )
                waiting.append((topic_key, event, cls, held))
                total += held
            at += n
        if at != size:
            raise ValueError("trailing bytes after the events")
        # Only a frame that parses to its end moves the sequence numbers.
        if expected is not None and expected != first:
            self._gaps.advance(supplier, type_name, expected, missed)
            if self._credits is not None:  # the frame has left the channel's queue
                self._credits.credit(supplier, type_name, expected)
        if cls is None:
            self.undecodable += count
        elif waiting:
            self.queue.dropped += keep_from
            self.queue.add(topic_key, waiting, total)

    def _credit_frame(self, body: memoryview, type_name: str) -> None:
        """Return the credit of a frame taken off the socket but not parsed into the queue."""
        found = next_due(body)
        if found is not None and self._credits is not None:
            self._credits.credit(found[0], type_name, found[1])

    def _hold(self, frame: tuple[bytes, memoryview], raw_hash: bytes, size: int) -> bool:
        """Keep a frame whose type is not known yet until the generated packages on the path
        are imported, off the reactor thread; False when that search is over (or too much
        waits already): then its type is unknown here."""
        if not self._searching:
            if registry.discovered():
                return False
            self._searching = True
            registry.discover_in_background(lambda: self.reactor.call_soon(self._release))
        if len(self._held) >= HOLD_FRAMES or self._held_bytes + size > HOLD_BYTES:
            return False
        self._held.append(frame)
        self._held_hashes.add(raw_hash)
        self._held_bytes += size
        return True

    def _release(self) -> None:
        """The search for generated packages is over: the frames that waited for it, in order."""
        self._searching = False
        held, self._held, self._held_hashes, self._held_bytes = self._held, [], set(), 0
        for frame in held:
            try:
                self._parse(*frame)
            except (ValueError, StructError, UnicodeDecodeError) as e:
                _peer_warnings.warning("dropped an event frame on %s: %s", self.channel.name, e)
        if len(self.queue):
            self._deliver()

    def close(self) -> None:
        offers.unsubscribed(self)
        self.link.close()
        if self._sweeper is not None:
            self.reactor.cancel_timer(self._sweeper)
        self.reactor.call_soon(self._segments.close)
        if self._credits is not None:
            self.reactor.call_soon(self._credits.close)


class _Shared:
    """A payload in shared memory, waiting in the queue: its segment and descriptor."""

    __slots__ = ("descriptor", "segment")

    def __init__(self, segment: shm.Segment, descriptor: shm.Descriptor) -> None:
        self.segment = segment
        self.descriptor = descriptor
