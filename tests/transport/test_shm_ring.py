"""A supplier's ring of slots and a reader's mapping of it (transport.shm), in one process:
orders of the two sides' steps that processes on a loaded host meet only now and then, made to
happen every time."""

from __future__ import annotations

import os

import pytest

from miro_gen.transport import shm

pytestmark = pytest.mark.skipif(not shm.available(), reason="shared memory needs Linux memfd")

SIZE = 4096


def test_a_reader_that_holds_a_write_as_the_ring_takes_its_slot_keeps_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The reader holds the slot's write after the ring found it free and before it writes
    (its process was not scheduled in between): the reader's check passes, so the ring must
    leave the slot to it (a zero-copy handler reads it in place) and write the next one."""
    ring = shm.Ring(SIZE, slots=2)
    first = ring.put(b"\x01" * SIZE)
    second = ring.put(b"\x02" * SIZE)
    assert first is not None and second is not None and first.slot != second.slot
    reader = shm.Segment(os.getpid(), ring.fd, ring.segment_id, False, 0)
    free_slot = ring._free_slot
    views: list[memoryview | None] = []

    def reader_comes_in_between(wait: float, keep_all: shm.KeepAll) -> int | None:
        slot = free_slot(wait, keep_all)
        if not views:
            assert slot == first.slot  # the oldest write goes first
            views.append(reader.hold(first))
        return slot

    monkeypatch.setattr(ring, "_free_slot", reader_comes_in_between)
    third = ring.put(b"\x03" * SIZE)
    view = views[0]
    assert view is not None  # it passed its check: it reads the slot in place
    assert third is not None and third.slot == second.slot
    assert bytes(view) == b"\x01" * SIZE and reader.current(first)
    view.release()
    reader.release(first, False)
    fourth = ring.put(b"\x04" * SIZE)  # released: the slot is free again
    assert fourth is not None and fourth.slot == first.slot and not reader.current(first)
    reader.close()
    ring.close()
