"""The Implementation base (the manual's integrateData pattern) behind a real server: polling
returns the latest value, wait-for-next wakes on the next one or raises ETimeOut, and every
value is published as an event."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import Miro
import Miro__POA
import pytest
import zmq
from loopback import NamingProcess, Recorder, eventually

from miro_gen import (
    Client,
    EventChannelFactory,
    Implementation,
    Server,
    StructuredPushSupplier,
)


class GpsImpl(Miro__POA.Gps, Implementation[Miro.GpsDataIDL]):
    def __init__(self, supplier: StructuredPushSupplier | None) -> None:
        Implementation.__init__(self, supplier, "Gps", initial=Miro.GpsDataIDL(), timeout=1.0)

    def getData(self) -> Miro.GpsDataIDL:
        return self.latest()

    def getWaitData(self) -> Miro.GpsDataIDL:
        return self.wait_next(Miro.ETimeOut)


def fix(n: int) -> Miro.GpsDataIDL:
    return Miro.GpsDataIDL(latitude=45.0 + n, longitude=-75.0, satellitesUsed=n)


@pytest.fixture
def gps() -> Iterator[tuple[GpsImpl, Miro.Gps, Recorder]]:
    naming = NamingProcess()
    args = ["t", "--naming", naming.endpoint, "-MNC", "rover"]
    server = Server(list(args), context=zmq.Context())
    channel = EventChannelFactory(server).create_channel()
    impl = GpsImpl(StructuredPushSupplier(channel))
    server.add_to_name_service(impl, "Gps")
    consumer = Recorder(channel)
    consumer.set_subscriptions([("rover", "Gps")])
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    client = Client(list(args), context=zmq.Context())
    try:
        yield impl, client.resolve_name("Gps", Miro.Gps), consumer
    finally:
        client.close()
        server.shutdown()
        thread.join(10)
        naming.stop()


def test_polling_returns_the_initial_then_the_latest_value(
    gps: tuple[GpsImpl, Miro.Gps, Recorder],
) -> None:
    impl, stub, _ = gps
    assert stub.getData().satellitesUsed == 0
    impl.integrate_data(fix(1))
    impl.integrate_data(fix(2))
    assert stub.getData().latitude == 47.0
    assert impl.count == 2


def test_wait_next_returns_the_next_value_not_the_current_one(
    gps: tuple[GpsImpl, Miro.Gps, Recorder],
) -> None:
    impl, stub, _ = gps
    impl.integrate_data(fix(1))
    got: list[Miro.GpsDataIDL] = []
    waiter = threading.Thread(target=lambda: got.append(stub.getWaitData()))
    waiter.start()
    eventually(lambda: impl.waiting == 1)  # the call waits on a worker of the server
    assert not got
    impl.integrate_data(fix(7))
    waiter.join(5)
    assert [g.satellitesUsed for g in got] == [7]


def test_many_waiters_are_woken_by_one_value(gps: tuple[GpsImpl, Miro.Gps, Recorder]) -> None:
    impl, stub, _ = gps
    got: list[int] = []
    waiters = [
        threading.Thread(target=lambda: got.append(stub.getWaitData().satellitesUsed))
        for _ in range(4)
    ]
    for w in waiters:
        w.start()
    eventually(lambda: impl.waiting == 4)
    impl.integrate_data(fix(3))
    for w in waiters:
        w.join(30)
    assert got == [3, 3, 3, 3]


def test_no_new_value_is_etimeout_at_the_client(gps: tuple[GpsImpl, Miro.Gps, Recorder]) -> None:
    _, stub, _ = gps
    start = time.monotonic()
    with pytest.raises(Miro.ETimeOut) as caught:
        stub.getWaitData()
    assert time.monotonic() - start > 0.9  # it waited for its timeout (a load only adds)
    assert "no new Gps value within 1 s" in caught.value.what


def test_every_value_is_published_with_its_stamp(gps: tuple[GpsImpl, Miro.Gps, Recorder]) -> None:
    impl, _, consumer = gps
    eventually(lambda: impl.supplier is not None and impl.supplier.has_subscribers("Gps"))
    for n in range(5):
        impl.integrate_data(fix(n), stamp=1000.0 + n)
    eventually(lambda: len(consumer.events) == 5)
    assert [e.payload.satellitesUsed for e in consumer.events] == [0, 1, 2, 3, 4]
    assert [e.stamp for e in consumer.events] == [1000.0, 1001.0, 1002.0, 1003.0, 1004.0]
    assert {(e.domain_name, e.type_name) for e in consumer.events} == {("rover", "Gps")}
    assert impl.published == 5


def test_without_a_supplier_only_polling() -> None:
    impl = GpsImpl(None)
    impl.integrate_data(fix(2))
    assert impl.latest().satellitesUsed == 2
    assert impl.published == 0
    bare: Implementation[int] = Implementation(None, "Count")
    with pytest.raises(LookupError, match="no Count value yet"):
        bare.latest()
    with pytest.raises(TimeoutError, match=r"no new Count value within 0\.01 s"):
        bare.wait_next(timeout=0.01)
