"""The player's file set (Miro's FileSet): several logs merged in log-time order, opened and
closed while it plays, the cut (with undo) and the topics left out.

Every event has a *key*, (log time, file number, segment offset, index in the segment): a
total order that does not depend on where reading started, so that the player can stand
between two events (a position is a key: the events at or after it are ahead), step forward
and back, and seek, over any number of files, with the same answer each time. Reading goes
segment by segment, read ahead and kept (eventlog.segments), so stepping back and forth around
the position reads nothing twice. Nothing here
knows about channels or Qt: the player (eventlog.player) plays what this yields, the window
(miro_gen.qt.logplayer) shows it, and eventlog.edit writes it to a new file.

`add`, `remove`, the cut and the exclusions may be called from any thread; listeners are told
of each change ("files", "cut", "excluded") after it is made.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable, Iterator
from typing import NamedTuple

from miro_gen.eventlog import segments
from miro_gen.eventlog.logfile import LogFile, Progress
from miro_gen.eventlog.reader import LogError, Topic
from miro_gen.eventlog.segments import START, Event, Key, TopicName, after, at_time

__all__ = ["START", "Event", "FileSet", "Key", "TopicInfo", "TopicName", "after", "at_time"]


class TopicInfo(NamedTuple):
    """A topic of the set, over all its files: its events and the type(s) it has."""

    name: TopicName
    events: int
    schema_names: tuple[str, ...]
    type_hashes: tuple[str, ...]


def topic_text(name: TopicName) -> str:
    return f"{name[0]}/{name[1]}"


class FileSet:
    """Logs merged in log-time order, with a cut and excluded topics."""

    def __init__(self, cache_segments: int = segments.CACHE_SEGMENTS) -> None:
        self._files: list[LogFile] = []  # replaced whole on a change, never changed in place
        self._numbers = itertools.count(1)
        self._lock = threading.Lock()
        self._cut: tuple[int, int] | None = None  # None: the whole span
        self._undo: list[tuple[int, int] | None] = []
        self.excluded: frozenset[TopicName] = frozenset()
        self.listeners: list[Callable[[str], object]] = []
        self._cache = segments.SegmentCache(cache_segments)

    # ---- files ----------------------------------------------------------------------------------

    @property
    def files(self) -> list[LogFile]:
        return self._files

    def paths(self) -> list[str]:
        return [f.path for f in self._files]

    def add(self, path: str, progress: Progress | None = None) -> LogFile:
        """Open the log at `path` into the set (LogError if it cannot be read, or is in the
        set already); from its summary, or scanned with `progress` when it has none."""
        real = os.path.realpath(path)
        if any(os.path.realpath(f.path) == real for f in self._files):
            raise LogError("it is open already")
        log = LogFile.open(path, next(self._numbers), progress)
        with self._lock:
            self._files = [*self._files, log]
        self._changed("files")
        return log

    def remove(self, path: str) -> None:
        """Close the log at `path` (KeyError if it is not in the set)."""
        with self._lock:
            log = next((f for f in self._files if f.path == path), None)
            if log is None:
                raise KeyError(path)
            self._files = [f for f in self._files if f is not log]
        log.close()
        self._cache.forget(log.number)
        self._changed("files")

    def close(self) -> None:
        with self._lock:
            files, self._files = self._files, []
        for f in files:
            f.close()
        self._cache.close()

    def warnings(self) -> list[tuple[str, str]]:
        """(path, warning) of every file that has one."""
        return [(f.path, w) for f in self._files for w in f.warnings]

    # ---- what the set holds ---------------------------------------------------------------------

    def span(self) -> tuple[int, int]:
        """Log times of the first and last events of all files ((0, 0) when there are none)."""
        files = [f for f in self._files if f.segments]
        if not files:
            return 0, 0
        return min(f.first_ns for f in files), max(f.last_ns for f in files)

    @property
    def count(self) -> int:
        return sum(f.count for f in self._files)

    def topics(self) -> list[TopicInfo]:
        """The topics of all files, merged by domain and type, sorted."""
        counts: dict[TopicName, int] = {}
        schemas: dict[TopicName, set[str]] = {}
        hashes: dict[TopicName, set[str]] = {}
        for f in self._files:
            for topic in f.topics.values():
                name = (topic.domain, topic.type_name)
                counts.setdefault(name, 0)
                schemas.setdefault(name, set()).add(topic.schema_name)
                hashes.setdefault(name, set()).add(topic.type_hash)
            for seg in f.segments:
                for cid, n in seg.counts.items():
                    t = f.topics.get(cid)
                    if t is not None:
                        counts[(t.domain, t.type_name)] += n
        return [
            TopicInfo(name, counts[name], tuple(sorted(schemas[name])), tuple(sorted(hashes[name])))
            for name in sorted(counts)
        ]

    def domains(self) -> list[str]:
        return sorted({t.domain for f in self._files for t in f.topics.values()})

    def density(self, buckets: int, start_ns: int, end_ns: int) -> dict[TopicName, list[float]]:
        """Events of each topic in `buckets` equal spans of [start_ns, end_ns], from the
        segments' counts alone (each segment's events spread evenly over its time span)."""
        out: dict[TopicName, list[float]] = {}
        width = max(1, end_ns - start_ns)
        for f in self._files:
            for seg in f.segments:
                if seg.end_ns < start_ns or seg.start_ns > end_ns:
                    continue
                first = (max(seg.start_ns, start_ns) - start_ns) * buckets // width
                last = (min(seg.end_ns, end_ns) - start_ns) * buckets // width
                first, last = min(first, buckets - 1), min(last, buckets - 1)
                share = 1 / (last - first + 1)
                for cid, n in seg.counts.items():
                    t = f.topics.get(cid)
                    if t is None:
                        continue
                    row = out.setdefault((t.domain, t.type_name), [0.0] * buckets)
                    for b in range(first, last + 1):
                        row[b] += n * share
        return out

    # ---- the cut and the exclusions -------------------------------------------------------------

    @property
    def cut(self) -> tuple[int, int]:
        """(first, last) log time played and saved: the whole span unless cut."""
        first, last = self.span()
        if self._cut is None:
            return first, last
        start, end = max(first, self._cut[0]), min(last, self._cut[1])
        return (start, end) if start <= end else (first, last)

    @property
    def is_cut(self) -> bool:
        return self._cut is not None and self.cut != self.span()

    def cut_front(self, log_ns: int) -> bool:
        """Leave out what comes before `log_ns` (Miro's Cut Front); False if that would leave
        nothing."""
        return self._set_cut(log_ns, self.cut[1])

    def cut_back(self, log_ns: int) -> bool:
        """Leave out what comes after `log_ns` (Cut Back); False if that would leave nothing."""
        return self._set_cut(self.cut[0], log_ns)

    def _set_cut(self, start: int, end: int) -> bool:
        if start > end or not self._files:
            return False
        with self._lock:
            self._undo.append(self._cut)
            self._cut = (start, end)
        self._changed("cut")
        return True

    def undo_cut(self) -> bool:
        """Take back the last cut (False when there is none)."""
        with self._lock:
            if not self._undo:
                return False
            self._cut = self._undo.pop()
        self._changed("cut")
        return True

    def undo_all(self) -> None:
        """The whole span again (Miro's Undo all)."""
        with self._lock:
            self._undo.clear()
            self._cut = None
        self._changed("cut")

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    def exclude(self, name: TopicName, excluded: bool = True) -> None:
        """Leave a topic out of what is played (or take it back in)."""
        with self._lock:
            now = self.excluded | {name} if excluded else self.excluded - {name}
            if now == self.excluded:
                return
            self.excluded = frozenset(now)
        self._changed("excluded")

    def is_excluded(self, topic: Topic) -> bool:
        return (topic.domain, topic.type_name) in self.excluded

    def _changed(self, what: str) -> None:
        for listener in list(self.listeners):
            listener(what)

    # ---- reading --------------------------------------------------------------------------------

    @property
    def segments_read(self) -> int:
        """How many segments were read from their files (not found among those kept)."""
        return self._cache.read

    def forward(self, pos: Key = START, end_ns: int | None = None) -> Iterator[Event]:
        """The events from position `pos` on (up to log time `end_ns`, included), in key
        order, excluded topics among them (the player skips those when it comes to them)."""
        return segments.forward(self._cache, self._files, pos, end_ns)

    def backward(self, pos: Key, start_ns: int | None = None) -> Iterator[Event]:
        """The events before position `pos` (down to log time `start_ns`, included), latest
        first."""
        return segments.backward(self._cache, self._files, pos, start_ns)

    def series(
        self,
        name: TopicName,
        value: Callable[[Event], float | None],
        start_ns: int,
        end_ns: int,
        buckets: int = 2000,
        progress: Progress | None = None,
    ) -> list[tuple[int, float]]:
        """(log time, value) of `value(event)` for the events of topic `name` between the
        two times: every one when they are few, else the lowest and the highest of each of
        `buckets` equal spans of time (a spike is never averaged away). Only the segments
        holding the topic are read; `progress` returning False stops early."""
        wanted = [
            (f, s)
            for f in self._files
            for s in f.segments
            if s.end_ns >= start_ns
            and s.start_ns <= end_ns
            and any(
                (f.topics[c].domain, f.topics[c].type_name) == name
                for c in s.counts
                if c in f.topics
            )
        ]
        width = max(1, end_ns - start_ns)
        low: dict[int, tuple[int, float]] = {}
        high: dict[int, tuple[int, float]] = {}
        for n, (log, seg) in enumerate(wanted):
            if progress is not None and not progress(n / max(1, len(wanted))):
                break
            for ev in self._cache.events(log, seg):
                if ev.name != name or not start_ns <= ev.key[0] <= end_ns:
                    continue
                v = value(ev)
                if v is None:
                    continue
                b = (ev.key[0] - start_ns) * buckets // width
                if b not in low or v < low[b][1]:
                    low[b] = (ev.key[0], v)
                if b not in high or v > high[b][1]:
                    high[b] = (ev.key[0], v)
        return sorted(set(low.values()) | set(high.values()))
