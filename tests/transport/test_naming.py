"""The naming service and Server/Client, between real processes on loopback."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import Miro
import MiroNaming
import pytest
import zmq
from loopback import NamingProcess, eventually, free_port, run_miro, service_env
from repo_paths import TESTS

from miro_gen import TRANSIENT, Client

HERE = TESTS
EXAMPLE = HERE / "procs" / "named_example.py"
RELAY = HERE / "procs" / "relay.py"
LEASE = "1.5"  # seconds: short, so that expiry is seen quickly


def env() -> dict[str, str]:
    return service_env(MIRO_TEST_LEASE=LEASE)


Naming = NamingProcess


class Service:
    def __init__(self, naming: Naming, *args: str, script: Path = EXAMPLE) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(script), "--naming", naming.endpoint, *args],
            stdout=subprocess.PIPE,
            text=True,
            env=env(),
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "READY"

    def stop(self, sig: int = signal.SIGTERM) -> int:
        self.proc.send_signal(sig)
        return self.proc.wait(10)


@pytest.fixture
def naming() -> Iterator[Naming]:
    n = Naming()
    yield n
    n.stop()


def client(naming: Naming, *args: str) -> Client:
    return Client(["test", "--naming", naming.endpoint, *args], context=zmq.Context())


def resolves(c: Client, name: str) -> bool:
    try:
        c.naming.resolve(name)
    except MiroNaming.NotFound:
        return False
    return True


def test_the_manuals_client_pattern(naming: Naming) -> None:
    """ExampleA binds, ExampleB resolves it by name and polls it (§5.1)."""
    service = Service(naming, "-MNC", "robot1")
    try:
        c = client(naming, "-MNC", "robot1")
        example = c.resolve_name("ExampleA", Miro.Example)
        example.setData(0.0, 10.0)
        assert example.getData() == Miro.ExampleStructIDL(1.0, 11.0)
        other = client(naming, "-MNC", "robot2")
        with pytest.raises(MiroNaming.NotFound, match="robot2/ExampleA"):
            other.resolve_name("ExampleA", Miro.Example)  # not in robot2's context, not at root
        by_path = other.resolve_name("robot1/ExampleA", Miro.Example)
        assert by_path.getData() == Miro.ExampleStructIDL(1.0, 11.0)
        c.close()
        other.close()
    finally:
        assert service.stop() == 0


def test_nslist_prints_the_tree(naming: Naming) -> None:
    a = Service(naming, "-MNC", "robot1")
    b = Service(naming, "-MNC", "robot1", "Second")
    try:
        out = run_miro("nslist", "--naming", naming.endpoint)
        assert out.returncode == 0, out.stderr
        lines = out.stdout.splitlines()
        assert lines[0] == "robot1/"
        assert lines[1].startswith("  ExampleA  (IDL:Miro/Example:1.0 at tcp://127.0.0.1:")
        assert lines[2].startswith("  Second  (IDL:Miro/Example:1.0 at tcp://")
    finally:
        a.stop()
        b.stop()


def test_a_stopped_server_unbinds_and_a_killed_one_expires(naming: Naming) -> None:
    c = client(naming)
    polite = Service(naming, "-MNC", "r", "Polite")
    killed = Service(naming, "-MNC", "r", "Killed")
    assert resolves(c, "r/Polite") and resolves(c, "r/Killed")
    assert polite.stop(signal.SIGINT) == 0
    assert not resolves(c, "r/Polite")  # unbound on the way out
    killed.stop(signal.SIGKILL)
    assert resolves(c, "r/Killed")  # until its lease runs out
    eventually(lambda: not resolves(c, "r/Killed"), 30)  # the deadline only stops the wait
    c.close()


def test_a_naming_service_restarted_without_its_log_is_repopulated(naming: Naming) -> None:
    """Its log lost, a naming service learns the names again from the servers' renewals."""
    service = Service(naming, "-MNC", "r")
    port = int(naming.endpoint.rsplit(":", 1)[1])
    naming.stop()
    time.sleep(0.2)
    again = Naming(port)  # a log of its own: empty
    try:
        c = client(again)
        eventually(lambda: resolves(c, "r/ExampleA"))
        assert c.resolve_name("r/ExampleA", Miro.Example).getData() == Miro.ExampleStructIDL(
            1.0, 1.0
        )
        c.close()
    finally:
        service.stop()
        again.stop()


def test_no_naming_service_is_transient(naming: Naming) -> None:
    c = Client(["t", "--naming", f"tcp://127.0.0.1:{free_port()}"], context=zmq.Context())
    with pytest.raises(TRANSIENT):
        c.resolve_name("ExampleA", Miro.Example)
    c.close()


def test_malformed_frames_to_the_naming_service(naming: Naming) -> None:
    rogue = zmq.Context.instance().socket(zmq.DEALER)
    rogue.setsockopt(zmq.LINGER, 0)
    rogue.connect(naming.endpoint)
    for parts in ([b"x"], [b"\x01\x01" + bytes(20), b"y"], [b""] * 4):
        rogue.send_multipart(parts)
    rogue.close()
    c = client(naming)
    assert not resolves(c, "nothing/here")
    with pytest.raises(MiroNaming.InvalidName):
        c.naming.registry.resolve("bad//name")
    c.close()


def test_a_servant_calling_back_into_its_caller_does_not_deadlock(naming: Naming) -> None:
    """A.getData calls B.getData, which calls A.setData while A still serves the first call:
    servants run on a worker pool, so A serves the call back."""
    a = Service(naming, "-MNC", "r", "A", "@B", script=RELAY)
    b = Service(naming, "-MNC", "r", "B", "A", script=RELAY)
    try:
        c = client(naming, "-MNC", "r")
        stub = c.resolve_name("A", Miro.Example)
        stub._timeout = 10.0
        assert stub.getData() == Miro.ExampleStructIDL(7.0, 8.0)  # B's call back reached A
        c.close()
    finally:
        a.stop()
        b.stop()
