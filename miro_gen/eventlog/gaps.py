"""Counting the events a consumer missed, from the suppliers' sequence numbers."""

from __future__ import annotations


class GapCounter:
    """Sequence numbers run per supplier and type (docs/PROTOCOL.md): an event whose number is
    past the next one expected means that many were lost (a high-water mark, a late join). A
    number back at or before the last one means the supplier restarted or a replay looped:
    counting starts again there."""

    def __init__(self) -> None:
        self._next: dict[tuple[int, str], int] = {}
        self.missed = 0

    def observe(self, supplier: int, type_name: str, seq: int) -> int:
        """How many events were missed just before this one."""
        key = (supplier, type_name)
        expected = self._next.get(key)
        self._next[key] = seq + 1
        if expected is None or seq <= expected:
            return 0
        self.missed += seq - expected
        return seq - expected
