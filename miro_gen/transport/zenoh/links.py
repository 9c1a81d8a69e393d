"""Suppliers' and consumers' links to an event channel over Zenoh (the `PublishingLink` and
`SubscribingLink` of transport.events.links).

A channel over Zenoh is a name, not a process: its events of one domain and type travel on one
key (`keys.event_key`), the batch frame (transport.events.frames) as the payload, routed by
Zenoh from every supplier to every consumer whose key expression matches. A consumer's
subscriptions become key expressions (`keys.event_selector`: `*` a key wildcard); one that
another of its subscriptions covers is not declared, so that no event comes twice.

Zenoh's subscriber callbacks run on Zenoh's threads: they only append (key, payload) to a
bounded queue and, when it was empty, ask the reactor to read it (`Reactor.call_soon`, which
never blocks). A full queue drops the newest event, which the consumer's sequence numbers
show as missed: a keep-last consumer's queue holds at most `hwm` frames, a keep-all
consumer's KEEP_ALL_BYTES of them, however many that is. Each subscription of a consumer is
also a liveliness token (`keys.sub_token`), which the suppliers of the channel count as
ZeroMQ's XPUB counts subscriptions: `has_subscribers()` is false while nobody listens (nothing
is encoded then), and a consumer whose process dies stops counting when its session ends.

Suppliers put from the reactor thread with congestion control DROP, so a slow consumer never
blocks them, except for the topics a keep-all consumer subscribes to (its token says so): those
go with BLOCK, so that Zenoh drops nothing on the way and a supplier faster than the network
waits for it (at most Zenoh's `transport/link/tx/queue/congestion_control/block/wait_before_close`,
after which Zenoh closes the link). Both kinds of publisher of a topic share the session's
queue, so events keep their order when a keep-all consumer comes or goes.

A fleet's channel: a consumer of the channel pattern `*/EventChannel` (resolve_channel with a
`*` in the name) hears that channel of every robot, each robot's events under its own domain
(Miro's NotifyMulticast, without a multicast group): its keys use Zenoh's `$*` wildcard, and
suppliers count its subscriptions when their channel matches the pattern. A consumer of its own
robot's channel hears the types its process shares with the fleet (transport.zenoh.fleet,
MIRO_FLEET_EVENTS) from that channel of every other robot too.
"""

from __future__ import annotations

import collections
import contextlib
import fnmatch
import itertools
import threading
from collections.abc import Callable
from typing import Any

import zenoh

from miro_gen.log import PeerWarnings, logger
from miro_gen.transport.events.frames import FrameError
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.zenoh import fleet, keys
from miro_gen.transport.zenoh.session import direct, identity, track, untrack

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)
_DROP = zenoh.CongestionControl.DROP
_BLOCK = zenoh.CongestionControl.BLOCK
_tokens = itertools.count(1)  # the subscription tokens of this process
# What a keep-all consumer's link holds for its reactor, at most (the consumer's own queue
# holds as much: transport.events.queue.QUEUE_BYTES).
KEEP_ALL_BYTES = 64 << 20


class ZenohChannels:
    """The links of the channels of a process: its `session` and its `reactor`. `endpoint`
    is what a channel's naming entry carries; `shared` the event types each channel (by its
    name without context) shares with the fleet (default: MIRO_FLEET_EVENTS)."""

    def __init__(self, session: Any, reactor: Reactor, shared: fleet.Shared | None = None) -> None:
        self.session = session
        self.reactor = reactor
        self.endpoint = keys.endpoint(identity(session))
        self.shared = fleet.from_environment() if shared is None else shared

    def publishing(
        self,
        channel: str,
        on_connection: Callable[[bool], object],
        on_subscriptions: Callable[[list[tuple[bool, bytes]]], object],
        hwm: int,
        burst: int,
    ) -> ZenohPublishing:
        if keys.is_pattern(channel):
            raise ValueError(f"{channel}: a fleet's channel pattern is for consumers only")
        return ZenohPublishing(self.session, self.reactor, channel, on_connection, on_subscriptions)

    def subscribing(
        self, channel: str, on_readable: Callable[[], object], hwm: int, *, keep_all: bool = False
    ) -> ZenohSubscribing:
        pattern = fleet.fleet_pattern(channel)
        types = self.shared.get(channel.rsplit("/", 1)[-1]) if pattern is not None else None
        return ZenohSubscribing(
            self.session,
            self.reactor,
            channel,
            on_readable,
            hwm,
            keep_all=keep_all,
            fleet=None if pattern is None or not types else (pattern, types),
        )


class ZenohPublishing:
    """A supplier's link: a Zenoh publisher per topic, declared on first use; one with
    congestion control BLOCK besides while a keep-all consumer subscribes to the topic."""

    def __init__(
        self,
        session: Any,
        reactor: Reactor,
        channel: str,
        on_connection: Callable[[bool], object],
        on_subscriptions: Callable[[list[tuple[bool, bytes]]], object],
    ) -> None:
        self.session = session
        self.channel = channel
        # Per topic: (the publisher in use, the generation of _keep_all it was chosen for).
        self._topics: dict[bytes, tuple[Any, int]] = {}
        self._publishers: dict[tuple[bytes, bool], Any] = {}  # (topic, blocking): publisher
        self._keep_all: dict[bytes, int] = {}  # keep-all consumers' prefixes: how many
        self._generation = 0  # bumped when _keep_all changes
        self._closed = False
        self._reactor = reactor
        self._on_subscriptions = on_subscriptions
        reactor.call_soon(on_connection, True)  # a channel that no process hosts is always up
        self._watch = track(
            session.liveliness().declare_subscriber(
                keys.SUB_TOKENS, direct(self._on_token), history=True
            )
        )

    def _on_token(self, sample: Any) -> None:  # Zenoh's thread: hand over, never block
        key = str(sample.key_expr)
        wanted = keys.sub_channel(key)
        if wanted is None or not (
            wanted == self.channel
            or (keys.is_pattern(wanted) and fnmatch.fnmatchcase(self.channel, wanted))
        ):
            return  # another channel's consumer
        try:
            prefix, keep_all = keys.prefix_of_sub(key)
        except FrameError:
            return
        subscribed = sample.kind == zenoh.SampleKind.PUT
        self._reactor.call_soon(self._subscription, subscribed, prefix, keep_all)

    def _subscription(self, subscribed: bool, prefix: bytes, keep_all: bool) -> None:
        """A consumer (un)subscribed (reactor thread)."""
        if keep_all:
            n = self._keep_all.get(prefix, 0) + (1 if subscribed else -1)
            if n > 0:
                self._keep_all[prefix] = n
            else:
                self._keep_all.pop(prefix, None)
            self._generation += 1
        self._on_subscriptions([(subscribed, prefix)])

    @property
    def connected(self) -> bool:
        return not self._closed

    @property
    def moves(self) -> int:
        return 0

    def send(self, topic: bytes, body: bytes, copy: bool) -> bool:
        known = self._topics.get(topic)
        if known is None or known[1] != self._generation:
            known = self._topics[topic] = (self._publisher(topic), self._generation)
        try:
            known[0].put(body if isinstance(body, bytes) else bytes(body))
        except zenoh.ZError:
            return False
        return True

    def _publisher(self, topic: bytes) -> Any:
        """The publisher for `topic` now: BLOCK while a keep-all consumer subscribes to it."""
        blocking = any(topic.startswith(p) for p in self._keep_all)
        publisher = self._publishers.get((topic, blocking))
        if publisher is None:
            publisher = self._publishers[topic, blocking] = self.session.declare_publisher(
                keys.event_key(self.channel, topic),
                congestion_control=_BLOCK if blocking else _DROP,
            )
        return publisher

    def close(self) -> None:
        self._closed = True
        untrack(self._watch)
        self._topics = {}
        publishers, self._publishers = list(self._publishers.values()), {}
        for p in publishers:
            with contextlib.suppress(zenoh.ZError):
                p.undeclare()


class ZenohSubscribing:
    """A consumer's link: a Zenoh subscriber per subscription not covered by another; at most
    `hwm` frames wait for the reactor, or for a keep-all consumer (`keep_all`: its suppliers
    then block rather than drop) KEEP_ALL_BYTES. `fleet` (the fleet's channel pattern and the
    types shared): the subscriptions also hear those types from every other robot's channel."""

    def __init__(
        self,
        session: Any,
        reactor: Reactor,
        channel: str,
        on_readable: Callable[[], object],
        hwm: int,
        *,
        keep_all: bool = False,
        fleet: tuple[str, frozenset[str]] | None = None,
    ) -> None:
        self.session = session
        self.reactor = reactor
        self.channel = channel
        self.keep_all = keep_all
        self.hwm = 1 << 62 if keep_all else hwm
        self.max_bytes = KEEP_ALL_BYTES if keep_all else 1 << 62
        self.dropped = 0  # frames the full queue refused
        self._bytes = 0  # of the frames waiting
        self._on_readable = on_readable
        self._prefixes: set[bytes] = set()
        self._subscribers: dict[bytes, Any] = {}
        self._tokens: dict[bytes, Any] = {}
        self._zid = str(session.zid())
        self._frames: collections.deque[tuple[str, bytes]] = collections.deque()
        self._scheduled = False
        self._lock = threading.Lock()  # the queue's size; only ever held for a few statements
        self._closed = False
        self._topics: dict[str, bytes] = {}  # event keys heard: their topic frames
        self._fleet = fleet
        self._own_keys = f"{keys.PREFIX}/ev/{keys.escape(channel)}/"  # (the fleet's hear them)
        self._fleet_subscribers: dict[bytes, list[Any]] = {}
        self._fleet_tokens: dict[bytes, list[Any]] = {}

    @property
    def connected(self) -> bool:
        return not self._closed

    @property
    def moves(self) -> int:
        return 0

    # ---- Zenoh's threads: never block -----------------------------------------------------------

    def _on_sample(self, sample: Any) -> None:
        payload = sample.payload.to_bytes()
        with self._lock:
            if len(self._frames) >= self.hwm or self._bytes + len(payload) > self.max_bytes:
                self.dropped += 1
                return
            self._bytes += len(payload)
            self._frames.append((str(sample.key_expr), payload))
        if not self._scheduled:
            self._scheduled = True
            self.reactor.call_soon(self._ready)

    def _on_fleet_sample(self, sample: Any) -> None:
        if not str(sample.key_expr).startswith(self._own_keys):  # (its own subscriber has it)
            self._on_sample(sample)

    # ---- the reactor thread ---------------------------------------------------------------------

    def _ready(self) -> None:
        self._scheduled = False
        if self._frames:
            self._on_readable()

    def subscribe(self, prefix: bytes) -> None:
        self._prefixes.add(prefix)
        self._declare()
        if prefix not in self._tokens:  # what suppliers count
            key = keys.sub_token(
                self.channel, prefix, self._zid, next(_tokens), keep_all=self.keep_all
            )
            self._tokens[prefix] = self.session.liveliness().declare_token(key)
            if self._fleet is not None:  # what the other robots' suppliers count
                pattern, types = self._fleet
                self._fleet_tokens[prefix] = [
                    self.session.liveliness().declare_token(
                        keys.sub_token(
                            pattern, token_prefix, self._zid, next(_tokens), keep_all=self.keep_all
                        )
                    )
                    for token_prefix in {t for _, t in _fleet_selectors(pattern, prefix, types)}
                ]

    def unsubscribe(self, prefix: bytes) -> None:
        self._prefixes.discard(prefix)
        self._declare()
        token = self._tokens.pop(prefix, None)
        if token is not None:
            _undeclare(token)
        for token in self._fleet_tokens.pop(prefix, []):
            _undeclare(token)

    def _declare(self) -> None:
        """Subscribers for the prefixes no other prefix covers (ZeroMQ's prefix rule)."""
        wanted = {
            p for p in self._prefixes if not any(q != p and p.startswith(q) for q in self._prefixes)
        }
        for p in [p for p in self._subscribers if p not in wanted]:
            untrack(self._subscribers.pop(p))
        for p in wanted - self._subscribers.keys():
            try:
                selector = keys.event_selector(self.channel, p)
            except (FrameError, UnicodeDecodeError) as e:
                _log.warning("cannot subscribe to %r: %s", p, e)
                continue
            self._subscribers[p] = track(
                self.session.declare_subscriber(selector, direct(self._on_sample))
            )
        if self._fleet is not None:
            self._declare_fleet(wanted)

    def _declare_fleet(self, wanted: set[bytes]) -> None:
        """The fleet's key expressions of the prefixes no other prefix covers."""
        assert self._fleet is not None
        pattern, types = self._fleet
        for p in [p for p in self._fleet_subscribers if p not in wanted]:
            for subscriber in self._fleet_subscribers.pop(p):
                untrack(subscriber)
        for p in wanted - self._fleet_subscribers.keys():
            self._fleet_subscribers[p] = [
                track(self.session.declare_subscriber(selector, direct(self._on_fleet_sample)))
                for selector, _ in _fleet_selectors(pattern, p, types)
            ]

    def receive(self) -> tuple[bytes, memoryview] | None:
        with self._lock:
            if not self._frames:
                return None
            key, payload = self._frames.popleft()
            self._bytes -= len(payload)
        topic = self._topics.get(key)
        if topic is None:
            try:
                topic = keys.topic_of(key)
            except (FrameError, UnicodeDecodeError) as e:
                raise ValueError(str(e)) from None
            if len(self._topics) >= 4096:  # bounded, whatever keys a wildcard brings
                self._topics.clear()
            self._topics[key] = topic
        return topic, memoryview(payload)

    def close(self) -> None:
        self._closed = True
        tokens, self._tokens = list(self._tokens.values()), {}
        for token in tokens:
            _undeclare(token)
        subscribers, self._subscribers = list(self._subscribers.values()), {}
        for s in subscribers:
            untrack(s)
        for group in [*self._fleet_tokens.values(), *self._fleet_subscribers.values()]:
            for entity in group:
                untrack(entity)  # (a token: undeclared)
        self._fleet_tokens, self._fleet_subscribers = {}, {}
        with self._lock:
            self._frames.clear()
            self._bytes = 0


def _fleet_selectors(pattern: str, prefix: bytes, types: frozenset[str]) -> list[tuple[str, bytes]]:
    """fleet.selectors, with a prefix no key can be made of left out (said once)."""
    try:
        return fleet.selectors(pattern, prefix, types)
    except (FrameError, UnicodeDecodeError) as e:
        _log.warning("cannot subscribe to %r across the fleet: %s", prefix, e)
        return []


def _undeclare(entity: Any) -> None:
    with contextlib.suppress(zenoh.ZError):
        entity.undeclare()
