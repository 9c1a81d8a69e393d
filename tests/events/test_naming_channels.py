"""`miro naming --channel NAME`: a channel hosted by the naming service outlives its suppliers."""

from __future__ import annotations

import time

import Miro
from loopback import NamingProcess, Recorder, RunningServer, eventually, run_miro

from miro_gen import EventChannelFactory, StructuredPushSupplier


def test_a_channel_hosted_by_naming_outlives_its_suppliers() -> None:
    naming = NamingProcess(options=("--channel", "Shared", "--channel", "robots/Status"))
    listener = RunningServer(naming.endpoint, "gui")
    try:
        listing = run_miro("nslist", "--naming", naming.endpoint).stdout
        assert "Shared  (IDL:miro-gen/EventChannel:1.0 at tcp://127.0.0.1:" in listing
        assert "robots/\n  Status  (IDL:miro-gen/EventChannel:1.0" in listing

        consumer = Recorder(listener.server.resolve_channel("Shared"))  # found from any context
        consumer.set_subscriptions([("*", "ExampleEvent")])
        for n in range(2):  # one supplier after another: the consumer does not notice
            supplier_proc = RunningServer(naming.endpoint, f"robot{n}")
            supplier = StructuredPushSupplier(supplier_proc.server.resolve_channel("Shared"))
            eventually(lambda s=supplier: s.has_subscribers("ExampleEvent"))
            payload = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(1.0, 2.0))
            supplier.push("ExampleEvent", payload)
            eventually(lambda n=n: len(consumer.events) == n + 1)
            supplier_proc.stop()
        assert [(e.domain_name, e.payload.counter) for e in consumer.events] == [
            ("robot0", 0),
            ("robot1", 1),
        ]
        time.sleep(4)  # longer than a lease: the naming service's own entries do not expire
        assert listener.server.resolve_channel("robots/Status").name == "robots/Status"
    finally:
        listener.stop()
        naming.stop()


def test_an_invalid_channel_name_is_a_usage_error() -> None:
    result = run_miro("naming", "--channel", "a//b")
    assert result.returncode == 2
    assert "--channel 'a//b' is not a valid name" in result.stderr


def test_find_or_create_uses_a_bound_channel_and_hosts_a_missing_one() -> None:
    naming = NamingProcess(options=("--channel", "Shared"))
    service = RunningServer(naming.endpoint, "robot")
    try:
        factory = EventChannelFactory(service.server)
        shared = factory.find_or_create_channel("Shared")
        assert shared.name == "Shared" and not service.server.hosted_channels
        mine = factory.find_or_create_channel("Mine")
        assert mine.name == "robot/Mine" and "robot/Mine" in service.server.hosted_channels
        assert factory.find_or_create_channel("Mine") is mine
    finally:
        service.stop()
        naming.stop()
