"""Reading a file set's events segment by segment: each event's key, the segments decoded into
events and kept (the last few), the next ones read ahead on a thread of their own, and the
merge of several files' segments in key order, forwards and backwards.

An event's *key* is (log time, file number, segment offset, index in the segment): a total
order that does not depend on where reading started. A position is a key too: the events at
or after it are ahead of it.

A segment is opened only when the next event due could be in it; its events are sorted once
and merged lazily (a heap entry per open segment, not per event), and the segment after it is
read ahead meanwhile, so that the thread playing the events never waits for a chunk to be
read and decompressed in the middle of playing.
"""

from __future__ import annotations

import contextlib
import heapq
import operator
import queue
import threading
from bisect import bisect_left
from collections import OrderedDict
from collections.abc import Iterator
from typing import NamedTuple

from mcap.records import Message

from miro_gen.eventlog.logfile import LogFile, Segment, SegmentError
from miro_gen.eventlog.reader import LogError, Topic

Key = tuple[int, int, int, int]  # log time, file number, segment offset, index in segment
TopicName = tuple[str, str]  # (domain, type name)
START: Key = (-1, -1, -1, -1)  # before every event
CACHE_SEGMENTS = 8  # segments kept decoded into events (about 1 MiB of data each)
READ_AHEAD = 2  # segments read ahead of the one opened
_KEY = operator.itemgetter(0)


class Event(NamedTuple):
    """One logged event, where it is in the set (`key`), its topic and its MCAP message."""

    key: Key
    topic: Topic
    message: Message

    @property
    def log_time(self) -> int:
        return self.key[0]

    @property
    def name(self) -> TopicName:
        return (self.topic.domain, self.topic.type_name)


def at_time(log_ns: int) -> Key:
    """The position before every event at `log_ns` or later."""
    return (log_ns, -1, -1, -1)


def after(key: Key) -> Key:
    """The position just after the event `key` (the next one is ahead of it)."""
    return (key[0], key[1], key[2], key[3] + 1)


class SegmentCache:
    """Segments decoded into events, sorted by key: the last `size` kept, more read ahead."""

    def __init__(self, size: int = CACHE_SEGMENTS) -> None:
        self.size = size
        self.read = 0  # segments read from their files (not found in the cache)
        self._cache: OrderedDict[tuple[int, int], list[Event]] = OrderedDict()
        self._reading: dict[tuple[int, int], threading.Event] = {}
        self._lock = threading.Lock()
        self._ahead: queue.SimpleQueue[tuple[LogFile, Segment] | None] = queue.SimpleQueue()
        self._worker: threading.Thread | None = None

    def events(self, log: LogFile, seg: Segment) -> list[Event]:
        """The segment's events in key order (read now unless kept or being read ahead)."""
        key = (log.number, seg.offset)
        while True:
            with self._lock:
                events = self._cache.get(key)
                if events is not None:
                    self._cache.move_to_end(key)
                    return events
                busy = self._reading.get(key)
                if busy is None:
                    busy = self._reading[key] = threading.Event()
                    break
            busy.wait()  # read ahead by the worker right now: take its result
        try:
            events = _decode(log, seg)
            with self._lock:
                self.read += 1
                if not log.closed:
                    self._cache[key] = events
                    while len(self._cache) > self.size:
                        self._cache.popitem(last=False)
            return events
        finally:
            with self._lock:
                del self._reading[key]
            busy.set()

    def read_ahead(self, log: LogFile, seg: Segment) -> None:
        """Read the segment on the worker thread, unless it is kept or being read."""
        key = (log.number, seg.offset)
        with self._lock:
            if key in self._cache or key in self._reading:
                return
            if self._worker is None:
                self._worker = threading.Thread(
                    target=self._work, name="miro-log-read", daemon=True
                )
                self._worker.start()
        self._ahead.put((log, seg))

    def _work(self) -> None:
        while True:
            job = self._ahead.get()
            if job is None:
                return
            with contextlib.suppress(LogError):  # said when the segment is played
                self.events(*job)

    def forget(self, number: int) -> None:
        """Drop the segments of file `number` (closed)."""
        with self._lock:
            for key in [k for k in self._cache if k[0] == number]:
                del self._cache[key]

    def close(self) -> None:
        with self._lock:
            self._cache.clear()
            worker, self._worker = self._worker, None
        if worker is not None:
            self._ahead.put(None)


def _decode(log: LogFile, seg: Segment) -> list[Event]:
    topics = log.topics
    events = []
    for i, m in enumerate(log.read(seg)):
        topic = topics.get(m.channel_id)
        if topic is None:
            raise SegmentError(
                log.path,
                f"chunk {seg.number} (at byte {seg.offset}): a message of the unknown channel "
                f"{m.channel_id}",
            )
        events.append(Event((m.log_time, log.number, seg.offset, i), topic, m))
    events.sort(key=_KEY)  # usually sorted already: a pass
    return events


def forward(
    cache: SegmentCache, files: list[LogFile], pos: Key, end_ns: int | None
) -> Iterator[Event]:
    """The events of `files` from position `pos` on, up to log time `end_ns` (included)."""
    chosen = sorted(
        ((s.start_ns, f.number, s.offset), f, s)
        for f in files
        for s in f.segments
        if s.end_ns >= pos[0] and (end_ns is None or s.start_ns <= end_ns)
    )
    heap: list[tuple[Key, int, list[Event], int]] = []
    i = 0
    while True:
        if i < len(chosen) and (not heap or chosen[i][0][0] <= heap[0][0][0]):
            _, log, seg = chosen[i]
            events = cache.events(log, seg)
            for _, ahead_log, ahead_seg in chosen[i + 1 : i + 1 + READ_AHEAD]:
                cache.read_ahead(ahead_log, ahead_seg)
            j = bisect_left(events, pos, key=_KEY)
            if j < len(events):
                heapq.heappush(heap, (events[j].key, i, events, j))
            i += 1
            continue
        if not heap:
            return
        key, n, events, j = heap[0]
        if end_ns is not None and key[0] > end_ns:
            return
        if j + 1 < len(events):
            heapq.heapreplace(heap, (events[j + 1].key, n, events, j + 1))
        else:
            heapq.heappop(heap)
        yield events[j]


def backward(
    cache: SegmentCache, files: list[LogFile], pos: Key, start_ns: int | None
) -> Iterator[Event]:
    """The events of `files` before position `pos`, down to log time `start_ns` (included),
    latest first."""
    chosen = sorted(
        (
            ((-s.end_ns, -f.number, -s.offset), f, s)
            for f in files
            for s in f.segments
            if s.start_ns <= pos[0] and (start_ns is None or s.end_ns >= start_ns)
        ),
        key=_KEY,
    )
    heap: list[tuple[Key, int, list[Event], int]] = []
    i = 0
    while True:
        if i < len(chosen) and (not heap or -chosen[i][0][0] >= -heap[0][0][0]):
            _, log, seg = chosen[i]
            events = cache.events(log, seg)
            for _, ahead_log, ahead_seg in chosen[i + 1 : i + 1 + READ_AHEAD]:
                cache.read_ahead(ahead_log, ahead_seg)
            j = bisect_left(events, pos, key=_KEY) - 1
            if j >= 0:
                heapq.heappush(heap, (_negated(events[j].key), i, events, j))
            i += 1
            continue
        if not heap:
            return
        key, n, events, j = heap[0]
        if start_ns is not None and -key[0] < start_ns:
            return
        if j > 0:
            heapq.heapreplace(heap, (_negated(events[j - 1].key), n, events, j - 1))
        else:
            heapq.heappop(heap)
        yield events[j]


def _negated(key: Key) -> Key:
    return (-key[0], -key[1], -key[2], -key[3])
