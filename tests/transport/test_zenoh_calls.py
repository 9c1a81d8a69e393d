"""How a server over Zenoh takes its calls (transport/zenoh/adapter.py): reader threads take
queries from Zenoh's channel; a servant call holds one of the slots, and calls beyond them wait
for one; a servant may call back into its own process; a server that stops answers the calls it
is running and refuses new ones. (@nonblocking while every slot is held: test_zenoh.py.)"""

from __future__ import annotations

import threading
from collections.abc import Iterator

import Miro
import Miro__POA
import pytest
from loopback import NamingProcess, RunningServer, eventually

from miro_gen import Client
from miro_gen.exceptions import TRANSIENT, CompletionStatus

pytest.importorskip("zenoh")

from miro_gen.transport.zenoh.adapter import DEFAULT_WORKERS


@pytest.fixture(scope="module")
def naming() -> Iterator[NamingProcess]:
    process = NamingProcess(options=("--zenoh",))
    yield process
    process.stop()


class _Held(Miro__POA.Example):
    """setData counts its calls and waits for `release`; getData answers how many ran."""

    def __init__(self, release: threading.Event) -> None:
        self.release = release
        self.lock = threading.Lock()
        self.ran = 0
        self.finished = 0

    def setData(self, a: float, b: float) -> None:
        with self.lock:
            self.ran += 1
        self.release.wait(60)
        with self.lock:
            self.finished += 1

    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(float(self.ran), float(self.finished))


class _Relay(Miro__POA.Example):
    """getData asks `target` (an object of the same process) and passes its answer on."""

    def __init__(self) -> None:
        self.target: Miro.Example | None = None

    def setData(self, a: float, b: float) -> None:
        pass

    def getData(self) -> Miro.ExampleStructIDL:
        assert self.target is not None
        got = self.target.getData()
        return Miro.ExampleStructIDL(got.a + 100, got.b)


def _calls(target: object, n: int) -> tuple[list[threading.Thread], list[BaseException]]:
    failed: list[BaseException] = []

    def call() -> None:
        try:
            target()  # type: ignore[operator]
        except BaseException as e:  # reported by the test
            failed.append(e)

    threads = [threading.Thread(target=call, daemon=True) for _ in range(n)]
    for t in threads:
        t.start()
    return threads, failed


def test_calls_beyond_the_slots_wait_for_one_and_each_runs_once(naming: NamingProcess) -> None:
    release = threading.Event()
    held = _Held(release)
    server = RunningServer(naming.endpoint, "slots", "--transport", "zenoh")
    server.server.add_to_name_service(held, "Held")
    client = Client(["t", "--transport", "zenoh", "--naming", naming.endpoint])
    threads: list[threading.Thread] = []
    try:
        stub = client.resolve_name("slots/Held", Miro.Example, wait=10)
        threads, failed = _calls(lambda: stub.setData(0.0, 0.0), DEFAULT_WORKERS + 4)
        eventually(lambda: held.ran == DEFAULT_WORKERS)  # every slot is held, four wait
        assert held.ran == DEFAULT_WORKERS
        release.set()
        for t in threads:
            t.join(30)
        assert not failed
        assert (held.ran, held.finished) == (DEFAULT_WORKERS + 4, DEFAULT_WORKERS + 4)
        assert stub.getData() == Miro.ExampleStructIDL(DEFAULT_WORKERS + 4.0, DEFAULT_WORKERS + 4.0)
    finally:
        release.set()
        for t in threads:
            t.join(10)
        client.close()
        server.stop()


def test_a_servant_calls_back_into_its_own_process_while_other_slots_are_held(
    naming: NamingProcess,
) -> None:
    release = threading.Event()
    held, relay = _Held(release), _Relay()
    server = RunningServer(naming.endpoint, "nest", "--transport", "zenoh")
    server.server.add_to_name_service(held, "Held")
    server.server.add_to_name_service(relay, "Relay")
    client = Client(["t", "--transport", "zenoh", "--naming", naming.endpoint])
    threads: list[threading.Thread] = []
    try:
        relay.target = server.server.resolve_name("nest/Held", Miro.Example, wait=10)
        held_stub = client.resolve_name("nest/Held", Miro.Example, wait=10)
        relay_stub = client.resolve_name("nest/Relay", Miro.Example, wait=10)
        # two slots left: the relay's call takes one, its call back into this process the other
        threads, failed = _calls(lambda: held_stub.setData(0.0, 0.0), DEFAULT_WORKERS - 2)
        eventually(lambda: held.ran == DEFAULT_WORKERS - 2)
        assert relay_stub.getData() == Miro.ExampleStructIDL(100.0 + DEFAULT_WORKERS - 2, 0.0)
        release.set()
        for t in threads:
            t.join(30)
        assert not failed and held.finished == DEFAULT_WORKERS - 2
    finally:
        release.set()
        for t in threads:
            t.join(10)
        client.close()
        server.stop()


def test_a_stopping_server_answers_the_call_under_way_and_refuses_new_ones(
    naming: NamingProcess,
) -> None:
    release = threading.Event()
    held = _Held(release)
    server = RunningServer(naming.endpoint, "stop", "--transport", "zenoh")
    server.server.add_to_name_service(held, "Held")
    server.server.drain_timeout = 60.0
    client = Client(["t", "--transport", "zenoh", "--naming", naming.endpoint])
    threads: list[threading.Thread] = []
    stopper = threading.Thread(target=server.stop, daemon=True)
    try:
        stub = client.resolve_name("stop/Held", Miro.Example, wait=10)
        threads, failed = _calls(lambda: stub.setData(0.0, 0.0), 1)
        eventually(lambda: held.ran == 1)
        stopper.start()
        refused: list[TRANSIENT] = []

        def refuses() -> bool:
            try:
                stub.getData()
            except TRANSIENT as e:
                refused.append(e)
                return True
            return False

        eventually(refuses)  # the server drains: new calls are refused, not run
        assert refused[0].completed == CompletionStatus.NO and "stopping" in str(refused[0])
        assert held.finished == 0 and stopper.is_alive()  # it waits for the call under way
        release.set()
        threads[0].join(30)
        stopper.join(30)
        assert not failed and held.finished == 1  # answered, as its caller saw
    finally:
        release.set()
        for t in threads:
            t.join(10)
        if stopper.is_alive() or not stopper.ident:
            server.stop()
        client.close()
