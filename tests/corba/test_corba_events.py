"""Events between miro-gen and a CORBA event channel (Debian's omniEvents, CosEventComm push
model with `any` payloads), both ways: a Python supplier to a C++ omniORB consumer, a C++
supplier to a Python consumer, and `miro bridge corba` relaying between the CORBA channel and a
miro-gen channel, so that unchanged StructuredPushSupplier/Consumer code sees the C++ side."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import zmq
from corba_peers import (
    CppPeer,
    OmniNames,
    missing_tools,
    readline,
    run_peer,
)
from loopback import NamingProcess, free_port, service_env
from miro_cli import REPO

from miro_gen import Client, Server
from miro_gen.corba.events import CosEventConsumer, CosEventSupplier, EventChannel
from miro_gen.transport.events import (
    EventChannelFactory,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)

pytestmark = [
    pytest.mark.skipif(
        bool(missing_tools()) or shutil.which("omniEvents") is None,
        reason=f"needs {', '.join(missing_tools()) or 'omnievents'}",
    ),
    pytest.mark.timeout(300),
]


@pytest.fixture(scope="module")
def channel_name(omninames: OmniNames) -> Iterator[str]:
    """omniEvents on a free port, and an event channel it made, bound in omniNames."""
    port = free_port()
    data = tempfile.mkdtemp(prefix="miro-omnievents-")
    ref = ("-ORBInitRef", f"NameService={omninames.url}")
    proc = subprocess.Popen(
        ["omniEvents", "-f", "-p", str(port), "-l", data, *ref],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 20
        while True:  # eventc fails until the factory is bound
            made = subprocess.run(["eventc", "-n", "TestChannel", *ref], capture_output=True)
            if made.returncode == 0:
                break
            assert time.monotonic() < deadline, made.stderr
            time.sleep(0.1)
        yield "TestChannel"
    finally:
        proc.kill()
        proc.wait(10)
        shutil.rmtree(data, ignore_errors=True)


class Collector(CosEventConsumer):
    def __init__(self, channel: EventChannel, expected: int) -> None:
        self.values: list[Any] = []
        self.expected = expected
        self.done = threading.Event()
        super().__init__(channel)

    def push_event(self, value: Any) -> None:
        self.values.append(value)
        if len(self.values) >= self.expected:
            self.done.set()


def test_a_python_supplier_and_a_cpp_consumer(
    peer_bin: Path, omninames: OmniNames, channel_name: str, peer_gen: SimpleNamespace
) -> None:
    P = peer_gen.Peer
    consumer = CppPeer(peer_bin, "consume", channel_name, "5", naming=omninames.url)
    client = Client(["test", "--naming", omninames.url], context=zmq.Context())
    try:
        assert consumer.readline() == "CONNECTED"
        supplier = CosEventSupplier(EventChannel.resolve(client, channel_name))
        supplier.push(P.Point(1, 2))
        supplier.push(P.Nested(name="from python", last=0.25))
        supplier.push(P.Point(-3, 4))
        supplier.push(42)
        supplier.push("hello")
        status, out = consumer.finish(30)
        assert status == 0, out
        assert out.splitlines() == [
            "EVENT Point 1 2",
            "EVENT Nested from python 0.25",
            "EVENT Point -3 4",
            "EVENT long 42",
            "EVENT string hello",
        ]
        supplier.close()
    finally:
        consumer.kill()
        client.close()


def test_a_cpp_supplier_and_a_python_consumer(
    peer_bin: Path, omninames: OmniNames, channel_name: str, peer_gen: SimpleNamespace
) -> None:
    P = peer_gen.Peer
    client = Client(["test", "--naming", omninames.url], context=zmq.Context())
    try:
        collector = Collector(EventChannel.resolve(client, channel_name), 4)
        status, out = run_peer(peer_bin, "push", channel_name, "3", naming=omninames.url)
        assert status == 0, out
        assert collector.done.wait(20), collector.values
        assert collector.values[:3] == [P.Point(0, 0), P.Point(1, 2), P.Point(2, 4)]
        nested = collector.values[3]
        assert isinstance(nested, P.Nested)
        assert (nested.name, nested.last, nested.outline) == ("nested-3", 1e300, P.Shape(4, 0.5))
        assert [list(row) for row in nested.m] == [[0, 1, 2], [3, 4, 5]]
        assert nested.flags == [True, False, True]
        collector.close()
    finally:
        client.close()


def test_the_bridge_relays_both_ways(
    peer_bin: Path, omninames: OmniNames, channel_name: str, peer_gen: SimpleNamespace
) -> None:
    P = peer_gen.Peer
    naming = NamingProcess()
    server = Server(["test", "--naming", naming.endpoint, "-MNC", "robot"], context=zmq.Context())
    channel = EventChannelFactory(server).create_channel("EventChannel")
    received: list[StructuredEvent] = []
    arrived = threading.Event()

    class Nesteds(StructuredPushConsumer):
        def push_structured_event(self, event: StructuredEvent) -> None:
            received.append(event)
            arrived.set()

    # Its own domain: a "*" one would subscribe to everything, and so make has_subscribers()
    # below true before the bridge subscribes.
    Nesteds(channel).set_subscriptions([("bridge", "Nested")])
    supplier = StructuredPushSupplier(channel)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    env = service_env()
    env["PYTHONPATH"] += f":{peer_gen.path}"
    corba = f"corbaname::127.0.0.1:{omninames.port}#{channel_name}"
    bridge = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "bridge", "corba", "--naming",
         naming.endpoint, "-MNC", "bridge", "--channel", "robot/EventChannel", "--corba",
         corba, "--to-corba", "*/Point",
         "--from-corba", "Peer::Nested"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=REPO,
    )  # fmt: skip
    consumer = CppPeer(peer_bin, "consume", channel_name, "2", naming=omninames.url)
    try:
        assert bridge.stdout is not None
        line = readline(bridge.stdout, 30, "the bridge")
        assert line.startswith("bridging"), line
        assert consumer.readline() == "CONNECTED"
        deadline = time.monotonic() + 20
        while not supplier.has_subscribers("Point"):  # the bridge subscribes (on its turn)
            assert time.monotonic() < deadline, "the bridge did not subscribe"
            time.sleep(0.02)
        supplier.push("Point", P.Point(5, 6))
        supplier.push("Point", P.Point(7, 8))
        status, out = consumer.finish(30)
        assert out.splitlines() == ["EVENT Point 5 6", "EVENT Point 7 8"], out
        status, out = run_peer(peer_bin, "push", channel_name, "1", naming=omninames.url)
        assert status == 0, out
        assert arrived.wait(20), "nothing came back from the CORBA channel"
        event = received[0]
        assert (event.domain_name, event.type_name) == ("bridge", "Nested")
        assert event.payload.name == "nested-1" and event.payload.last == 1e300
    finally:
        consumer.kill()
        bridge.terminate()
        bridge.wait(10)
        server.shutdown()
        thread.join(10)
        naming.stop()


def test_the_bridge_refuses_circles_and_says_what_is_missing() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "bridge", "corba", "--corba", "IOR:00",
         "--to-corba", "*/Point", "--from-corba", "Point"],
        capture_output=True, text=True, env=service_env(), cwd=REPO, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2 and "Point both ways" in done.stderr
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "bridge", "corba", "--corba", "IOR:00"],
        capture_output=True, text=True, env=service_env(), cwd=REPO, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2 and "nothing to bridge" in done.stderr
