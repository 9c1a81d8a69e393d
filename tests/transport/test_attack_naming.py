"""The naming service and servers under attack (issue 21), between real processes: per-name
renewal, made-up operations, oversized frames and listings, floods that must not starve lease
renewals, and a cap on connections (who may change a name: test_attack_owners.py). Memory
bounds are checked generously and apart from load; bench/bench_floods.py measures them."""

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
from loopback import NamingProcess, RunningServer, eventually, rss_mb, run_miro, service_env
from repo_paths import TESTS

from miro_gen import BAD_OPERATION, MARSHAL, TRANSIENT, Client
from miro_gen.runtime.cdr import HEADER_LE
from miro_gen.transport.naming.client import NAMING_KEY, list_entries
from miro_gen.transport.rpc import frames

HERE = TESTS
EXAMPLE = HERE / "procs" / "named_example.py"


class Victim:
    """named_example.py binding `names` under the context `r`: a server others attack."""

    def __init__(self, naming: NamingProcess, *names: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(EXAMPLE), "--naming", naming.endpoint, "-MNC", "r", *names],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "READY"

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)


@pytest.fixture
def naming() -> Iterator[NamingProcess]:
    n = NamingProcess()
    yield n
    n.stop()


def client(naming: NamingProcess, *args: str) -> Client:
    return Client(["t", "--naming", naming.endpoint, *args], context=zmq.Context())


def entry(name: str, endpoint: str = "tcp://10.66.6.6:666") -> MiroNaming.Entry:
    return MiroNaming.Entry(name, Miro.Example._repo_id, endpoint, b"evil", "")


def test_a_server_binds_again_each_name_it_lost(naming: NamingProcess) -> None:
    """Renewal answers name by name: a server holding two names that loses one binds that one
    again (before, `renew` said yes as long as any of its names lived)."""
    server = RunningServer(naming.endpoint, "r")
    c = client(naming)
    try:
        for name in ("One", "Two"):
            server.server.add_to_name_service(ExampleServant(), name)
        owner = c.naming.registry_stub(c.invoker, 5.0, owner=True)  # this user, as the server
        owner.unbind_as("r/One", server.server.owner)  # lost, as if expired
        with pytest.raises(MiroNaming.NotFound):
            c.naming.registry.resolve("r/One")
        eventually(lambda: _resolves(c, "r/One"))
        assert _resolves(c, "r/Two")
    finally:
        c.close()
        server.stop()


def _resolves(c: Client, name: str) -> bool:
    try:
        c.naming.registry.resolve(name)
    except MiroNaming.NotFound:
        return False
    return True


class ExampleServant(Miro__POA.Example):
    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(1.0, 2.0)

    def setData(self, a: float, b: float) -> None:
        pass


def _request(operation: str, oneway: bool, request_id: int = 1) -> list[bytes]:
    header = frames.encode_request(frames.Request(request_id, NAMING_KEY, operation, 0, oneway))
    return [header, bytes(HEADER_LE)]


def test_made_up_operations_leave_the_naming_service_as_it_was(naming: NamingProcess) -> None:
    """Before: every (class, operation) received was cached, 65 KB made-up names included:
    16,000 of them grew the naming service by about 1 GB. Now: BAD_OPERATION, nothing kept."""
    rogue = zmq.Context.instance().socket(zmq.DEALER)
    rogue.setsockopt(zmq.LINGER, 0)
    rogue.connect(naming.endpoint)
    before = rss_mb(naming.proc.pid)
    for n in range(4000):  # 260 MB of operation names
        rogue.send_multipart(_request(f"{n:08d}" + "x" * 65_000, oneway=True))
    rogue.send_multipart(_request("nothing", oneway=False, request_id=7))
    assert rogue.poll(60_000), "no answer to the request after the flood"
    head, _ = rogue.recv_multipart()
    reply = frames.decode_reply(head)
    assert reply.request_id == 7 and reply.repo_id == BAD_OPERATION._repo_id
    grown = rss_mb(naming.proc.pid) - before
    assert grown < 100, f"the naming service grew by {grown:.0f} MiB"
    rogue.close()
    c = client(naming)
    assert not _resolves(c, "still/serving")
    c.close()


def test_the_adapter_caches_only_operations_that_exist(naming: NamingProcess) -> None:
    server = RunningServer(naming.endpoint, "r")
    try:
        ref = server.server.add_to_name_service(ExampleServant(), "A")
        invoker = server.server.invoker
        for n in range(50):
            reply = invoker.invoke(ref, f"made_up_{n}", bytes(HEADER_LE), timeout=5)
            assert reply is not None and reply.repo_id == BAD_OPERATION._repo_id
        stub = server.server.resolve_name("r/A", Miro.Example)
        assert stub.getData() == Miro.ExampleStructIDL(1.0, 2.0)
        assert {op for _, op in server.server.adapter._quick} == {"getData"}
    finally:
        server.stop()


def test_oversized_messages_are_refused_with_marshal_and_lists_come_in_pages() -> None:
    """A request larger than the maximum message size is MARSHAL at the caller; a peer that
    sends one anyway is disconnected. A listing larger than a message comes in pages (before:
    MARSHAL, and `miro nslist` failed with a full table)."""
    naming = NamingProcess(options=("--max-message-size", "64K"))
    c = client(naming, "--max-message-size", "64K")
    registry = c.naming.registry_stub(c.invoker, 5.0, owner=True)
    me = MiroNaming.Owner("r/big", "run")
    try:
        with pytest.raises(MARSHAL, match="maximum message size"):
            registry.bind_as(entry("x/big", "tcp://" + "e" * 70_000), me, 1000, False)
        for n in range(100):  # each entry ~1 KB: the list is larger than 64K
            registry.bind_as(entry(f"x/{n:04d}" + "n" * 900), me, 60_000, False)
        names = [e.name for e in list_entries(c.naming.registry, "x/")]
        assert names == [f"x/{n:04d}" + "n" * 900 for n in range(100)]
        page = c.naming.registry.list_page("x/", "", 1000)
        assert page.more and 0 < len(page.entries) < 64
        assert c.naming.resolve("x/0001" + "n" * 900).name.startswith("x/0001")
        out = run_miro("nslist", "--naming", naming.endpoint, "--max-message-size", "64K")
        assert out.returncode == 0, out.stderr
        assert out.stdout.count("(IDL:Miro/Example:1.0 at") == 100
    finally:
        c.close()
        naming.stop()


def _flood(endpoint: str, size: int, stop: threading.Event, sent: list[int]) -> None:
    """Stream frames of `size` bytes to `endpoint` until `stop`, reconnecting when dropped."""
    ctx = zmq.Context()
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.SNDHWM, 4)
    s.connect(endpoint)
    junk = _request("x", oneway=True)[0]
    payload = bytes(size)
    while not stop.is_set():
        try:
            s.send_multipart([junk, payload], zmq.NOBLOCK)
            sent[0] += 1
        except zmq.Again:
            time.sleep(0.005)
    s.close()
    ctx.term()


def test_bulk_traffic_does_not_starve_lease_renewals(naming: NamingProcess) -> None:
    """Before: four connections streaming 50 MB frames took the naming service and a server to
    2.3-2.5 GB and starved lease renewals, so a live server's names expired. Now frames over
    the maximum size close their connection, the others are answered in turn with the
    renewals, and the names stay bound all along."""
    victim = Victim(naming, "A")
    c = client(naming)
    target = c.naming.resolve("r/A").endpoint
    stop = threading.Event()
    sent = [0]
    floods = [
        threading.Thread(target=_flood, args=(where, size, stop, sent), daemon=True)
        for where, size in (
            (naming.endpoint, 50 << 20),  # over the limit: dropped with the connection
            (naming.endpoint, 50 << 20),
            (naming.endpoint, 6 << 20),  # under it: read, and answered
            (target, 50 << 20),
        )
    ]
    try:
        for f in floods:
            f.start()
        checks = 0
        end = time.monotonic() + 2.5 * 3.0  # two and a half leases, and enough of both
        while time.monotonic() < end or (
            min(checks, sent[0]) <= 10 and time.monotonic() < end + 30
        ):
            assert _resolves(c, "r/A"), "the victim's name expired during the flood"
            checks += 1
            time.sleep(0.1)
        assert sent[0] > 10 and checks > 10
        assert rss_mb(naming.proc.pid) < 500
        assert rss_mb(victim.proc.pid) < 500
    finally:
        stop.set()
        for f in floods:
            f.join(10)
        c.close()
        victim.stop()


def test_connections_beyond_the_cap_are_refused() -> None:
    naming = NamingProcess(options=("--max-connections", "3"))
    clients = [client(naming) for _ in range(4)]
    try:
        for c in clients[:3]:
            assert not _resolves(c, "a/b")  # each keeps its connection
        with pytest.raises(TRANSIENT, match="refused the connection"):
            clients[3].naming.registry.resolve("a/b")
        clients[0].close()
        eventually(lambda: _try_resolve(clients[3]))
    finally:
        for c in clients[1:]:
            c.close()
        naming.stop()


def _try_resolve(c: Client) -> bool:
    try:
        return not _resolves(c, "a/b")
    except TRANSIENT:
        return False
