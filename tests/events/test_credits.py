"""Keep-all consumers' credits (transport.events.credits): the table a consumer writes and its
suppliers read, the announcing subscription, and the window of frames a supplier keeps in
flight, with its bound (counted: the clock is passed in)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from miro_gen.transport import shm
from miro_gen.transport.events import credits

pytestmark = pytest.mark.skipif(not shm.available(), reason="credits need Linux memfd")

MARKER = credits.credit_marker()


@pytest.fixture
def table() -> Iterator[credits.CreditTable]:
    t = credits.CreditTable(entries=4)
    yield t
    t.close()


def reader_of(table: credits.CreditTable, prefix: bytes = b"s\0") -> credits.CreditReader:
    found = credits.parse_subscription(MARKER, table.subscription(MARKER, prefix))
    assert found is not None and found[1] == prefix
    return credits.CreditReader(*found[0])


def test_a_supplier_reads_the_credits_its_consumer_writes(table: credits.CreditTable) -> None:
    r = reader_of(table)
    key = credits.type_key("Tick")
    assert r.due(7, key) is None  # nothing from supplier 7 yet
    table.credit(7, "Tick", 10)
    table.credit(8, "Tick", 3)
    assert (r.due(7, key), r.due(8, key), r.due(7, credits.type_key("Tock"))) == (10, 3, None)
    table.credit(7, "Tick", 2**64)  # a spoofed number past the last: kept within 64 bits
    assert r.due(7, key) == 2**64 - 1
    for s in range(9, 20):  # a full table gives no more entries, and raises nothing
        table.credit(s, "Tick", 1)
    assert r.due(10, key) == 1 and r.due(11, key) is None  # four entries
    assert r.alive()
    r.close()


def test_subscriptions_that_are_not_credits_are_not_taken_for_them() -> None:
    assert credits.parse_subscription(MARKER, b"s\0Tick\0") is None
    assert credits.parse_subscription(MARKER, MARKER + b"short") is None
    assert credits.parse_subscription(b"", b"anything") is None
    suppliers = credits.KeepAllConsumers(MARKER)
    assert not suppliers.change(True, b"s\0Tick\0")
    # a table that is not there (a lie, or a consumer gone): refused, not raised
    ghost = MARKER + credits.ANNOUNCE.pack(2**31, 3, 42) + b"s\0"
    assert suppliers.change(True, ghost) and suppliers.refused == 1
    assert suppliers.matching(b"s\0Tick\0") == []


def test_the_window_holds_frames_back_until_credits_return(table: credits.CreditTable) -> None:
    suppliers = credits.KeepAllConsumers(MARKER)
    assert suppliers.change(True, table.subscription(MARKER, b"s\0"))
    readers = suppliers.matching(b"s\0Tick\0")
    assert len(readers) == 1 and suppliers.matching(b"t\0Tick\0") == []
    flow = credits.Flow(credits.type_key("Tick"), window=3)
    for seq in range(3):  # three frames of one event each
        assert flow.room(readers, 7, 0.0, 1.0)
        flow.sending(seq)
    assert not flow.room(readers, 7, 0.1, 1.0)  # three in flight, none read
    table.credit(7, "Tick", 2)  # frames 0 and 1 read
    assert flow.room(readers, 7, 0.2, 1.0)
    assert flow.sent == [2]  # what every consumer has read is forgotten
    assert flow.stalls == 0
    suppliers.change(False, table.subscription(MARKER, b"s\0"))
    assert suppliers.matching(b"s\0Tick\0") == []
    suppliers.close()


def test_a_silent_consumer_is_waited_for_once_then_not_until_it_reads_again(
    table: credits.CreditTable,
) -> None:
    r = reader_of(table)
    flow = credits.Flow(credits.type_key("Tick"), window=2)
    for seq in range(2):
        assert flow.room([r], 7, 0.0, 1.0)
        flow.sending(seq)
    assert not flow.room([r], 7, 0.0, 1.0)
    assert not flow.room([r], 7, 0.9, 1.0)  # still within the bound
    assert flow.room([r], 7, 1.0, 1.0)  # the bound waited: sent on without it
    for seq in range(2, 50):  # and not waited for again, frame after frame
        assert flow.room([r], 7, 1.0, 1.0)
        flow.sending(seq)
    assert flow.stalls == 1
    table.credit(7, "Tick", 50)  # it reads again: waited for again, with its credits
    assert flow.room([r], 7, 2.0, 1.0)
    flow.sending(50)
    flow.sending(51)
    assert not flow.room([r], 7, 2.0, 1.0)
    r.close()


def test_a_consumer_whose_table_is_gone_is_not_waited_for() -> None:
    t = credits.CreditTable()
    r = reader_of(t)
    flow = credits.Flow(credits.type_key("Tick"), window=1)
    flow.sending(0)
    t.close()  # the consumer's process has no fd of it any more, as after kill -9
    assert not r.alive()
    assert flow.room([r], 7, 0.0, 1.0)  # at once, not after the bound
    assert flow.stalls == 1
    r.close()


def test_a_table_closed_by_another_thread_is_not_alive_and_raises_nothing(
    table: credits.CreditTable,
) -> None:
    """The reactor thread closes a table whose consumer unsubscribed while a replay's thread,
    with the reader in a list from before, may be asking whether its consumer is alive."""
    r = reader_of(table)
    fd = r.fd
    r.close()
    assert not r.alive()
    assert not shm.holds_open(r.pid, r.consumer_fd, fd)  # our descriptor closed: not an error


def test_a_ring_waits_for_one_lane_per_live_keep_all_consumer() -> None:
    """The lanes a supplier's ring waits for (transport.shm): one per keep-all consumer that
    takes the topic, not one per subscription, and none for a consumer whose process is gone
    while its subscriptions still count (they are on their way through the channel)."""
    a, b = credits.CreditTable(), credits.CreditTable()
    suppliers = credits.KeepAllConsumers(MARKER)
    frame = b"s\0Image\0"
    for t in (a, b):
        assert suppliers.change(True, t.subscription(MARKER, frame))
    assert suppliers.change(True, a.subscription(MARKER, b"s\0"))  # a: both s/Image and s/*
    assert suppliers.lanes(frame, 3) == 2  # three keep-all subscriptions, two consumers
    assert suppliers.lanes(frame, 4) == 3  # and one whose table is not mapped here: counted
    assert suppliers.lanes(b"s\0Tick\0", 1) == 1  # a takes it through s/*: one subscription
    # A supplier that connected after them heard each keep-all prefix once: still two lanes.
    assert suppliers.lanes(frame, 2) == 2
    b.close()  # kill -9 of b: nothing of its process holds the table any more
    assert suppliers.lanes(frame, 3) == 1
    a.close()
    assert suppliers.lanes(frame, 3) == 0
    suppliers.close()


def test_a_dead_consumer_is_given_up_once_per_flow_when_two_suppliers_share_a_type() -> None:
    """A replay of two robots has a flow of one type from each (two suppliers): a consumer
    gone is given up once in each, not again and again as each flow finds the other's credit
    where it stopped waiting."""
    t = credits.CreditTable()
    r = reader_of(t)
    t.credit(7, "Tick", 20)
    t.credit(8, "Tick", 21)
    flows = {s: credits.Flow(credits.type_key("Tick"), window=1) for s in (7, 8)}
    for s, flow in flows.items():
        flow.sending(30 + s)  # a frame beyond its credit: the consumer is behind in both
    t.close()  # gone, as after kill -9
    for _ in range(5):
        for s, flow in flows.items():
            assert flow.room([r], s, 0.0, 1.0)
    assert [f.stalls for f in flows.values()] == [1, 1]
    r.close()
