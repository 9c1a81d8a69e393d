"""Counting the events a consumer missed, from the suppliers' sequence numbers.

Sequence numbers run per supplier and type (docs/PROTOCOL.md): an event whose number is past
the next one expected means that many were lost on the way (a high-water mark, a host that
restarted). Numbers come from the network, so they are not trusted: a number back at or before
the last one, or one more than MAX_GAP ahead of it, means the supplier restarted, a replay
looped, or someone lies; counting starts again there and nothing is counted as missed. The
state is bounded: past MAX_SOURCES (supplier, type) pairs the least recently seen is forgotten.
"""

from __future__ import annotations

MAX_SOURCES = 4096  # (supplier, type name) pairs remembered
MAX_GAP = 1 << 24  # a larger jump is a restart (or a lie), not 16 million lost events


def gap(expected: int | None, seq: int) -> int:
    """Events missed just before `seq` when `expected` was the next number due (None: first)."""
    if expected is None or seq <= expected or seq - expected > MAX_GAP:
        return 0
    return seq - expected


class GapCounter:
    """The next sequence number due per (supplier, type name), and the events missed."""

    def __init__(self, max_sources: int = MAX_SOURCES) -> None:
        self._next: dict[tuple[int, str], int] = {}
        self.max_sources = max_sources
        self.missed = 0

    def expected(self, supplier: int, type_name: str) -> int | None:
        """The next number due from this supplier and type (None: none seen yet)."""
        return self._next.get((supplier, type_name))

    def advance(self, supplier: int, type_name: str, next_seq: int, missed: int) -> None:
        """Record that `next_seq` is due next, after `missed` events were lost."""
        key = (supplier, type_name)
        table = self._next
        if table.pop(key, None) is None and len(table) >= self.max_sources:
            del table[next(iter(table))]  # the least recently seen
        table[key] = next_seq
        self.missed += missed

    def observe(self, supplier: int, type_name: str, seq: int) -> int:
        """How many events were missed just before this one."""
        missed = gap(self.expected(supplier, type_name), seq)
        self.advance(supplier, type_name, seq + 1, missed)
        return missed
