"""A consumer's events waiting for delivery, kept as its quality of service says.

A consumer reads its socket as fast as events arrive and hands them to `push_structured_event`
from this queue, so a slow handler no longer leaves events piling up in ZeroMQ's queues (where
they grew seconds old and nobody counted them). Like ROS 2's keep-last history, the queue keeps
per topic (domain, type) the newest `depth` events waiting (default 10), never splitting the
events one supplier pushed in one turn (they arrive together in one frame); `latest_only`
keeps only the newest one per topic; `KEEP_ALL` keeps everything. Whatever the setting, the
queue holds at most `max_bytes` of payloads (the oldest go first). What is evicted is counted in
`dropped` (and what the byte bound evicted in `overflowed` too: a keep-all consumer counts it as
lost, in `missed`); payloads are decoded only when delivered.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Final

from miro_gen.transport.events.event import StructuredEvent

if TYPE_CHECKING:
    from miro_gen.runtime.datatypes import IdlType

KEEP_ALL = 0
DEFAULT_DEPTH = 10  # ROS 2's default history depth
QUEUE_BYTES = 64 << 20


# One event received and not yet delivered: (topic, a StructuredEvent whose payload is still
# the CDR bytes, the generated type that decodes it, the payload's size). A plain tuple: one is
# made for every event received, and a class's __init__ cost as much as the rest of receiving.
Waiting = tuple[tuple[str, str], StructuredEvent, "type[IdlType]", int]
TOPIC: Final = 0  # where a Waiting has its topic
SIZE: Final = 3  # and its payload's size


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
        self.overflowed = 0  # of which by the byte bound
        self.bytes = 0
        self._live = 0
        self._order: deque[Waiting] = deque()
        self._evicted: set[int] = set()  # ids of the entries in _order evicted meanwhile
        # Per topic, for keep-last: the same entries, oldest first.
        self._topics: dict[tuple[str, str], deque[Waiting]] | None = {} if self.depth else None

    def __len__(self) -> int:
        return self._live

    def add(self, topic: tuple[str, str], waiting: list[Waiting], size: int | None = None) -> None:
        """The events of one frame (one topic), oldest first; `size`: their sizes' sum, if
        known."""
        if self.latest_only and len(waiting) > 1:
            self.dropped += len(waiting) - 1
            waiting = waiting[-1:]
            size = None
        self._order.extend(waiting)
        self._live += len(waiting)
        self.bytes += sum(w[SIZE] for w in waiting) if size is None else size
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
            evicted = self._evicted
            self._order = deque(w for w in self._order if id(w) not in evicted)
            evicted.clear()

    def pop(self) -> Waiting | None:
        """The oldest event waiting, or None."""
        order, evicted = self._order, self._evicted
        while order:
            w = order.popleft()
            if evicted and id(w) in evicted:
                evicted.discard(id(w))
                continue
            if self._topics is not None:
                queue = self._topics[w[TOPIC]]
                queue.popleft()  # w: the oldest of its topic too
                if not queue:
                    del self._topics[w[TOPIC]]
            self._live -= 1
            self.bytes -= w[SIZE]
            return w
        return None

    def take(self, limit: int) -> list[Waiting]:
        """The oldest events waiting, at most `limit`, oldest first (as `pop` would give them)."""
        order = self._order
        if self._topics is None and not self._evicted:  # keep-all: every entry is live
            taken = [order.popleft() for _ in range(min(limit, len(order)))]
            self._live -= len(taken)
            self.bytes -= sum(w[SIZE] for w in taken)
            return taken
        taken = []
        pop = self.pop
        while len(taken) < limit:
            w = pop()
            if w is None:
                break
            taken.append(w)
        return taken

    def put_back(self, taken: list[Waiting]) -> None:
        """Events `take` gave and that were not delivered, back in front, in their order."""
        for w in reversed(taken):
            self._order.appendleft(w)
            if self._topics is not None:
                queue = self._topics.get(w[TOPIC])
                if queue is None:
                    queue = self._topics[w[TOPIC]] = deque()
                queue.appendleft(w)
            self._live += 1
            self.bytes += w[SIZE]

    def _evict(self, w: Waiting) -> None:
        self._evicted.add(id(w))  # it stays in _order (skipped there) until popped or compacted
        self._live -= 1
        self.bytes -= w[SIZE]
        self.dropped += 1

    def _evict_oldest(self) -> None:
        w = self.pop()
        if w is not None:
            self.dropped += 1
            self.overflowed += 1

    def clear(self) -> None:
        self.dropped += self._live
        self._order.clear()
        self._evicted.clear()
        if self._topics is not None:
            self._topics.clear()
        self._live = 0
        self.bytes = 0
