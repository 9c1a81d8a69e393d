"""Stubs follow their name: a client outlives restarts of its server, and waits for a server
that is not there yet (real processes: `miro naming`, servers and clients of their own)."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import Miro
import Miro__POA
import MiroNaming
import pytest
import zmq
from loopback import NamingProcess, free_port, service_env
from repo_paths import TESTS

from miro_gen import COMM_FAILURE, OBJECT_NOT_EXIST, TRANSIENT, Client, Server

HERE = TESTS
EXAMPLE = HERE / "procs" / "named_example.py"
SERVICES = HERE.parent / "services"


class Example:
    """tests/procs/named_example.py: ExampleA's servant bound as ExampleA in context `test`."""

    def __init__(self, naming: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(EXAMPLE), "--naming", naming, "-MNC", "test"],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "READY"  # bound

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait(10)

    def kill_when_busy(self) -> None:
        """Kill it once its servant has begun a setData(a < 0): the call has reached it (a
        timer instead may fire, on a loaded machine, before the request has left the caller)."""
        assert self.proc.stdout is not None
        if self.proc.stdout.readline().strip() == "BUSY":
            self.kill()


@pytest.fixture
def client(naming: str) -> Iterator[Client]:
    c = Client(["test", "--naming", naming, "-MNC", "test"], context=zmq.Context())
    yield c
    c.close()


def test_a_stub_follows_its_server_through_a_restart(naming: str, client: Client) -> None:
    first = Example(naming)
    stub = client.resolve_name("ExampleA", Miro.Example)
    try:
        stub.setData(5.0, 6.0)
        assert stub.getData() == Miro.ExampleStructIDL(6.0, 7.0)
        old = stub._ref
    finally:
        first.kill()
    # The old binding is all naming has: nowhere to go. A call sent before this process heard
    # the connection close is COMM_FAILURE (completed MAYBE, as it must be: the client cannot
    # know); once it has heard, calls are TRANSIENT, completed NO.
    gone = None
    for _ in range(100):
        try:
            stub.getData()
        except COMM_FAILURE as e:
            assert e.completed.name == "MAYBE"
            time.sleep(0.05)
            continue
        except TRANSIENT as e:
            gone = e
        break
    assert gone is not None and gone.completed.name == "NO"
    second = Example(naming)  # a new port and a new key, bound in place of the old
    try:
        for _ in range(3):  # the same stub, the first call after the new binding included
            assert stub.getData() == Miro.ExampleStructIDL(1.0, 1.0)  # the new server's state
        assert stub._ref != old
    finally:
        second.kill()


def test_a_call_that_may_have_run_is_not_sent_again(naming: str, client: Client) -> None:
    """At most once: a server killed during setData gives COMM_FAILURE, and its successor does
    not receive that setData."""
    first = Example(naming)
    stub = client.resolve_name("ExampleA", Miro.Example)
    stub._timeout = 30.0
    threading.Thread(target=first.kill_when_busy, daemon=True).start()
    second: Example | None = None
    try:
        with pytest.raises(COMM_FAILURE):
            stub.setData(-20.0, 9.0)  # the servant sleeps 20 s first
        second = Example(naming)
        assert stub.getData() == Miro.ExampleStructIDL(1.0, 1.0)  # setData never reached it
    finally:
        first.kill()
        if second is not None:
            second.kill()


def test_an_object_gone_from_its_server_is_looked_up_again(naming: str, client: Client) -> None:
    """OBJECT_NOT_EXIST (completed NO) from the old address: the name now leads elsewhere."""

    class Fixed(Miro__POA.Example):
        def __init__(self, value: float) -> None:
            self.value = value

        def setData(self, a: float, b: float) -> None:
            pass

        def getData(self) -> Miro.ExampleStructIDL:
            return Miro.ExampleStructIDL(self.value, self.value)

    servers = [Server(["t", "--naming", naming, "-MNC", "test"], context=zmq.Context())]
    servers.append(Server(["t", "--naming", naming, "-MNC", "test"], context=zmq.Context()))
    try:
        ref = servers[0].add_to_name_service(Fixed(1.0), "Moving")
        stub = client.resolve_name("Moving", Miro.Example)
        assert stub.getData().a == 1.0
        servers[0].adapter.deactivate(ref.key)
        servers[0].remove_from_name_service("Moving")  # (else its lease keeps the name)
        servers[1].add_to_name_service(Fixed(2.0), "Moving")
        assert stub.getData().a == 2.0
        stub._set_rebind(None)  # per stub: this one no longer follows the name
        servers[1].adapter.deactivate(stub._ref.key)
        servers[1].remove_from_name_service("Moving")
        servers[0].add_to_name_service(Fixed(3.0), "Moving")
        with pytest.raises(OBJECT_NOT_EXIST):
            stub.getData()
    finally:
        for server in servers:
            server.shutdown()
            server._cleanup()


def test_resolve_name_waits_for_the_name(naming: str, client: Client) -> None:
    with pytest.raises(MiroNaming.NotFound):
        client.resolve_name("Later", Miro.Example, wait=0.2)
    found: list[Miro.Example] = []
    waiter = threading.Thread(
        target=lambda: found.append(client.resolve_name("ExampleA", Miro.Example, wait=60))
    )
    waiter.start()
    server = Example(naming)
    try:
        waiter.join(60)
        assert found and found[0].getData() == Miro.ExampleStructIDL(1.0, 1.0)
    finally:
        server.kill()


def test_a_client_started_before_its_server_waits_then_polls() -> None:
    """ExampleB --wait, and even the naming service started after it."""
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    common = ["--naming", endpoint, "-MNC", "robot"]
    b = subprocess.Popen(
        [sys.executable, str(SERVICES / "exampleB.py"), *common, "--wait", "60", "--count", "2",
         "--period", "0.1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )  # fmt: skip
    a = naming = None
    try:
        naming = NamingProcess(port=int(endpoint.rsplit(":", 1)[1]))
        a = subprocess.Popen(
            [sys.executable, str(SERVICES / "exampleA.py"), *common],
            stdout=subprocess.DEVNULL,
            env=service_env(),
        )
        out, err = b.communicate(timeout=60)
        assert b.returncode == 0, err
        assert "Retrieved variables a and b are: 3 and 13" in out
    finally:
        for proc in (a, b):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait(10)
        if naming is not None:
            naming.stop()
