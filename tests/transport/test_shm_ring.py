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


def test_a_keep_all_consumer_that_stops_reading_is_waited_for_once_and_costs_others_nothing() -> (
    None
):
    """A keep-all consumer stops reading (SIGSTOP, a hung handler, a starved process) with the
    ring's slots unread. Before: every put waited the bound for it and then dropped the event,
    for every consumer of the topic (a healthy keep-all consumer beside it lost an event per
    second it was stopped; seen as a gap in test_shm_events' kill -9 test on a loaded host).
    Now, as with the credits, it is waited for once, then the ring goes on without it until it
    reads on; then it is waited for again."""
    ring = shm.Ring(SIZE, slots=2)
    stopped = shm.Segment(os.getpid(), ring.fd, ring.segment_id, True, 0)
    healthy = shm.Segment(os.getpid(), ring.fd, ring.segment_id, True, 0)
    written = []
    for n in range(6):
        d = ring.put(bytes([n]) * SIZE, 2, wait=0.01)
        assert d is not None, f"event {n} dropped"
        written.append(d)
        healthy.ack(d.write + 1)  # it reads each at once; `stopped` reads none
    assert ring.stalls == 1  # waited for once (at the third event), not per event
    assert not stopped.current(written[0])  # what it did not read was rewritten: it drops it
    stopped.ack(written[-1].write + 1)  # it reads on (the newest)...
    for n in range(6, 9):
        d = ring.put(bytes([n]) * SIZE, 2, wait=0.01)
        assert d is not None, f"event {n} dropped"
        healthy.ack(d.write + 1)
    assert ring.stalls == 2  # ... so it was waited for again, and given up again
    for s in (stopped, healthy):
        s.close()
    ring.close()


def test_a_keep_all_subscription_without_a_lane_is_waited_for_once() -> None:
    """Two keep-all consumers subscribed, one lane in the ring: the other has yet to map it, or
    its subscription outlived it (seen after a consumer stopped longer than the heartbeats'
    timeout, then killed). Before: every put waited the bound and dropped the event, for every
    consumer, for as long as that subscription stayed (the supplier sent nothing for a minute).
    Now a put waits for it once; then, the counts unchanged, the ring goes on."""
    ring = shm.Ring(SIZE, slots=2)
    mapped = shm.Segment(os.getpid(), ring.fd, ring.segment_id, True, 0)
    for n in range(6):
        d = ring.put(bytes([n]) * SIZE, 2, wait=0.01)
        assert d is not None, f"event {n} dropped"
        mapped.ack(d.write + 1)
    assert ring.stalls == 1
    mapped.close()
    ring.close()
