"""A consumer's events waiting for delivery, kept as its quality of service says.

A consumer reads its socket as fast as events arrive and hands them to `push_structured_event`
from this queue, so a slow handler no longer leaves events piling up in ZeroMQ's queues (where
they grew seconds old and nobody counted them). Like ROS 2's keep-last history, the queue keeps
per topic (domain, type) the newest `depth` events waiting (default 10), never splitting the
events one supplier pushed in one turn (they arrive together in one frame); `latest_only`
keeps only the newest one per topic; `KEEP_ALL` keeps everything. Whatever the setting, the
queue holds at most `max_bytes` of payloads (the oldest go first). What is evicted is counted in
`dropped`; payloads are decoded only when delivered.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

from miro_gen.transport.events.event import StructuredEvent

if TYPE_CHECKING:
    from miro_gen.runtime.datatypes import IdlType

KEEP_ALL = 0
DEFAULT_DEPTH = 10  # ROS 2's default history depth
QUEUE_BYTES = 64 << 20


class Waiting:
    """One event received and not yet delivered (its payload still encoded)."""

    __slots__ = ("alive", "cls", "event", "size", "topic")

    def __init__(
        self, topic: tuple[str, str], event: StructuredEvent, cls: type[IdlType], size: int
    ) -> None:
        self.topic = topic
        self.event = event  # a StructuredEvent whose payload is the CDR bytes
        self.cls = cls  # the generated type that decodes it
        self.size = size
        self.alive = True


class EventQueue:
    """Events waiting for delivery, in the order they arrived."""

    def __init__(
        self, depth: int = DEFAULT_DEPTH, latest_only: bool = False, max_bytes: int = QUEUE_BYTES
    ) -> None:
        if depth < 0:
            raise ValueError("depth is 0 (keep all) or more")
        self.depth = 1 if latest_only else depth
        self.latest_only = latest_only
        self.max_bytes = max_bytes
        self.dropped = 0  # events evicted before delivery
        self.bytes = 0
        self._live = 0
        self._order: deque[Waiting] = deque()
        # Per topic, for keep-last: the same entries, oldest first.
        self._topics: dict[tuple[str, str], deque[Waiting]] | None = {} if self.depth else None

    def __len__(self) -> int:
        return self._live

    def add(self, topic: tuple[str, str], waiting: list[Waiting]) -> None:
        """The events of one frame (one topic), oldest first."""
        if self.latest_only and len(waiting) > 1:
            self.dropped += len(waiting) - 1
            waiting = waiting[-1:]
        self._order.extend(waiting)
        self._live += len(waiting)
        self.bytes += sum(w.size for w in waiting)
        if self._topics is not None:
            queue = self._topics.get(topic)
            if queue is None:
                queue = self._topics[topic] = deque()
            queue.extend(waiting)
            limit = 1 if self.latest_only else max(self.depth, len(waiting))
            while len(queue) > limit:
                self._evict(queue.popleft())
        while self.bytes > self.max_bytes and self._live:
            self._evict_oldest()
        if len(self._order) > 2 * self._live + 1024:  # evicted entries still in the order
            self._order = deque(w for w in self._order if w.alive)

    def pop(self) -> Waiting | None:
        """The oldest event waiting, or None."""
        order = self._order
        while order:
            w = order.popleft()
            if not w.alive:
                continue
            if self._topics is not None:
                queue = self._topics[w.topic]
                queue.popleft()  # w: the oldest of its topic too
                if not queue:
                    del self._topics[w.topic]
            self._live -= 1
            self.bytes -= w.size
            return w
        return None

    def _evict(self, w: Waiting) -> None:
        w.alive = False
        self._live -= 1
        self.bytes -= w.size
        self.dropped += 1

    def _evict_oldest(self) -> None:
        w = self.pop()
        if w is not None:
            self.dropped += 1

    def clear(self) -> None:
        self.dropped += self._live
        self._order.clear()
        if self._topics is not None:
            self._topics.clear()
        self._live = 0
        self.bytes = 0
