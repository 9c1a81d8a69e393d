"""Large events (megabytes: camera images, point clouds) through event channels over real
sockets: they arrive whole and in order among small ones, travel alone, and the queues that
hold them shrink so that a slow consumer cannot make anybody's memory grow without end."""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable, Iterator

import Miro
import pytest
import zmq
from loopback import Recorder, RunningServer, eventually

from miro_gen import EventChannelFactory, Server, StructuredPushSupplier
from miro_gen.transport.events import HWM, LARGE_EVENT, PROXY_HWM, _hwm

FRAME_HEADERS = 44 + 28  # the batch header and the event header (docs/PROTOCOL.md)


@pytest.fixture
def servers(naming: str) -> Iterator[Callable[[str], Server]]:
    started: list[RunningServer] = []

    def make(context: str) -> Server:
        r = RunningServer(naming, context)
        started.append(r)
        return r.server

    yield make
    for r in reversed(started):
        r.stop()


def cloud(n: int, floats: int) -> Miro.Range3dScanEventIDL:
    """A scan whose intensities are `floats` numbers that say which scan they belong to."""
    values = array("f", range(floats))
    values[0] = n
    return Miro.Range3dScanEventIDL(Miro.TimeIDL(n, 0), intensity=values)


def test_megabyte_events_arrive_whole_and_in_order_among_small_ones(
    servers: Callable[[str], Server],
) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Clouds")
    supplier = StructuredPushSupplier(channel)
    remote = Recorder(servers("c").resolve_channel("r/Clouds"))
    local = Recorder(channel)  # in the host's process: the in-process endpoint
    for c in (remote, local):
        c.set_subscriptions([("*", "*")])
    eventually(lambda: len(supplier._subscriptions) >= 1)
    time.sleep(0.3)
    sizes = [10, 1 << 18, 5, 3 << 18, 1, 1, 1 << 16, 2]  # floats: 40 B ... 3 MB
    for n, floats in enumerate(sizes):
        supplier.push("Cloud", cloud(n, floats))
    for c in (remote, local):
        eventually(lambda c=c: len(c.events) == len(sizes), 30)  # type: ignore[misc]
        got = [e.payload for e in c.events]
        assert [p.time.sec for p in got] == list(range(len(sizes)))
        assert [len(p.intensity) for p in got] == sizes
        assert all(p.intensity[1:] == array("f", range(1, len(p.intensity))) for p in got)
        assert [e.seq for e in c.events] == list(range(len(sizes))) and c.missed == 0
    assert supplier.dropped == 0


def test_queues_shrink_for_large_frames(servers: Callable[[str], Server]) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Big")
    supplier = StructuredPushSupplier(channel)
    consumer = Recorder(servers("c").resolve_channel("r/Big"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("Cloud"))
    assert supplier.socket.getsockopt(zmq.SNDHWM) == HWM
    assert channel._host is not None and channel._host.hwm == PROXY_HWM
    small = cloud(0, 10)
    supplier.push("Cloud", small)
    eventually(lambda: len(consumer.events) == 1)
    assert consumer.socket.getsockopt(zmq.RCVHWM) == HWM  # small frames: as many as before
    big = cloud(1, 6 << 18)  # 6 MB
    supplier.push("Cloud", big)
    eventually(lambda: len(consumer.events) == 2, 30)
    frame = len(big.serialize()) + FRAME_HEADERS
    assert frame > LARGE_EVENT and _hwm(frame) < 16
    eventually(lambda: supplier.socket.getsockopt(zmq.SNDHWM) == _hwm(frame))
    assert consumer.socket.getsockopt(zmq.RCVHWM) == _hwm(frame)
    eventually(lambda: channel._host is not None and channel._host.hwm == _hwm(frame))
    # The channel still forwards after lowering its marks.
    supplier.push("Cloud", cloud(2, 10))
    eventually(lambda: len(consumer.events) == 3)
    assert consumer.missed == 0


def test_a_slow_consumer_of_large_events_misses_them_rather_than_hoarding_them(
    servers: Callable[[str], Server],
) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Slow")
    supplier = StructuredPushSupplier(channel)
    slow = Recorder(servers("c").resolve_channel("r/Slow"), delay=0.1)
    slow.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers("Cloud"))
    scan = cloud(0, 1 << 20)  # 4 MB: about 16 fit in each queue
    total = 100
    for _ in range(total):
        supplier.push("Cloud", scan)
        time.sleep(0.002)
    tail = cloud(1, 1)

    def tail_came() -> bool:  # a gap shows when an event after it comes
        supplier.push("Cloud", tail)
        time.sleep(0.2)
        return any(e.payload.time.sec == 1 for e in slow.events)

    eventually(tail_came, 60)
    # What was queued somewhere is bounded by the high-water marks, not by `total`: the rest
    # was dropped, and the consumer knows how much.
    first_tail = next(e.seq for e in slow.events if e.payload.time.sec == 1)
    before = [e for e in slow.events if e.seq < first_tail]
    assert len(before) < total / 2
    assert slow.missed == first_tail - len(before)
