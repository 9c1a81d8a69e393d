"""What only the Zenoh backbone has to show: its keys, the choice of backbone, and that a
session other than a name's owner cannot answer for it (Zenoh lets any session declare a
queryable on any key). The contract both backbones keep is tests/transport/test_backbones.py."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import Miro
import Miro__POA
import pytest
from hypothesis import given
from hypothesis import strategies as st
from loopback import NamingProcess, RunningServer, eventually, service_env

from miro_gen import Client, StructuredEvent, StructuredPushConsumer, nonblocking
from miro_gen.exceptions import TIMEOUT
from miro_gen.service.options import UsageError, parse_common_options
from miro_gen.transport.events import KEEP_ALL, EventChannel
from miro_gen.transport.events.frames import topic

zenoh = pytest.importorskip("zenoh")

from miro_gen.transport.rpc import frames  # noqa: E402
from miro_gen.transport.zenoh import keys  # noqa: E402
from miro_gen.transport.zenoh.adapter import DEFAULT_WORKERS  # noqa: E402
from miro_gen.transport.zenoh.session import config, identity, locator  # noqa: E402


@given(st.text())
def test_a_chunk_escapes_into_one_key_chunk_and_back(text: str) -> None:
    chunk = keys.escape(text)
    assert chunk and not set(chunk) & set("/*$?#")
    assert keys.unescape(chunk) == text


@given(st.text(), st.text(), st.text())
def test_an_event_key_gives_back_its_topic(channel: str, domain: str, type_name: str) -> None:
    t = topic(domain, type_name)
    if domain.count("\0") or type_name.count("\0"):
        return  # not a topic frame (a name has no NUL)
    key = keys.event_key(channel, t)
    assert keys.topic_of(key) == t
    if "*" not in channel:  # (a pattern is for consumers: it has no keys of its own)
        selector = zenoh.KeyExpr(keys.event_selector(channel, b""))
        assert selector.intersects(zenoh.KeyExpr(key))
        fleet = zenoh.KeyExpr(keys.event_selector("*" + channel[len(channel) // 2 :], b""))
        assert fleet.intersects(zenoh.KeyExpr(key))


def test_subscriptions_become_key_expressions() -> None:
    assert keys.event_selector("r/Events", b"") == "miro/ev/r%2FEvents/*/*"
    assert keys.event_selector("r/Events", b"robot1\0") == "miro/ev/r%2FEvents/robot1/*"
    assert keys.event_selector("E", topic("a/b", "T")) == "miro/ev/E/a%2Fb/T"


def test_the_backbone_is_chosen_by_option_or_environment() -> None:
    assert parse_common_options([])[0].transport == "zmq"
    assert parse_common_options(["--transport", "zenoh"])[0].transport == "zenoh"
    assert parse_common_options(["--transport=zenoh"])[0].transport == "zenoh"
    assert parse_common_options([], {"MIRO_TRANSPORT": "zenoh"})[0].transport == "zenoh"
    with pytest.raises(UsageError, match="unknown transport"):
        parse_common_options(["--transport", "dds"])


def test_sessions_never_scout_beyond_loopback() -> None:
    conf = config("client", connect=locator("tcp://127.0.0.1:1"))
    assert conf.get_json("scouting/multicast/enabled") == "false"
    assert conf.get_json("connect/endpoints") == '["tcp/127.0.0.1:1"]'


class _Example(Miro__POA.Example):
    def __init__(self) -> None:
        self.data = Miro.ExampleStructIDL(7.0, 7.0)

    def setData(self, a: float, b: float) -> None:
        self.data = Miro.ExampleStructIDL(a, b)

    def getData(self) -> Miro.ExampleStructIDL:
        return self.data


@pytest.fixture(scope="module")
def naming() -> Iterator[NamingProcess]:
    process = NamingProcess(options=("--zenoh",))
    yield process
    process.stop()


def test_a_second_session_on_the_owners_key_answers_no_call(naming: NamingProcess) -> None:
    owner = RunningServer(naming.endpoint, "robot1", "--transport", "zenoh")
    owner.server.add_to_name_service(_Example(), "ExampleA")
    rogue = zenoh.open(config("client", connect=locator(naming.endpoint)))
    heard = threading.Event()

    def answer(query: object) -> None:  # answers at once, as the owner would
        header = frames.decode_request(query.attachment.to_bytes())  # type: ignore[attr-defined]
        reply = Miro.ExampleStructIDL(-1.0, -1.0).serialize()
        query.reply(  # type: ignore[attr-defined]
            query.key_expr,  # type: ignore[attr-defined]
            reply,
            attachment=frames.reply_header(header.request_id, 0),
        )
        heard.set()

    queryable = rogue.declare_queryable(keys.call_key(identity(owner.server.zenoh)), answer)
    client = Client(["t", "--transport", "zenoh", "--naming", naming.endpoint])
    try:
        example = client.resolve_name("robot1/ExampleA", Miro.Example, wait=10)
        answers = [example.getData() for _ in range(20)]
        assert heard.is_set()  # the rogue heard the calls, and answered them
        assert answers == [Miro.ExampleStructIDL(7.0, 7.0)] * 20
        assert client.invoker.foreign_replies >= 1  # type: ignore[attr-defined]
    finally:
        client.close()
        queryable.undeclare()
        rogue.close()
        owner.stop()


class _Busy(Miro__POA.Example):
    """setData waits for `release`; getData answers at once, marked @nonblocking when the
    class says so."""

    def __init__(self, release: threading.Event) -> None:
        self.release = release
        self.ran = 0

    def setData(self, a: float, b: float) -> None:
        self.ran += 1
        self.release.wait(60)

    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(float(self.ran), 0.0)


class _QuickBusy(_Busy):
    @nonblocking
    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(float(self.ran), 0.0)


def test_a_nonblocking_method_is_answered_while_every_worker_blocks(
    naming: NamingProcess,
) -> None:
    """An operation marked @nonblocking runs on the thread that read it, as over ZeroMQ: it is
    answered while every worker slot of the server is held by a servant that blocks, where an
    unmarked one waits for a slot (its caller gives up)."""
    release = threading.Event()
    plain, quick = _Busy(release), _QuickBusy(release)
    server = RunningServer(naming.endpoint, "busy", "--transport", "zenoh")
    server.server.add_to_name_service(plain, "Plain")
    server.server.add_to_name_service(quick, "Quick")
    client = Client(["t", "--transport", "zenoh", "--naming", naming.endpoint])
    blocked: list[threading.Thread] = []
    try:
        plain_stub = client.resolve_name("busy/Plain", Miro.Example, wait=10)
        quick_stub = client.resolve_name("busy/Quick", Miro.Example, wait=10)
        for _ in range(DEFAULT_WORKERS):
            t = threading.Thread(target=plain_stub.setData, args=(0.0, 0.0), daemon=True)
            t.start()
            blocked.append(t)
        eventually(lambda: plain.ran == DEFAULT_WORKERS)  # every worker is held
        assert [quick_stub.getData() for _ in range(5)] == [Miro.ExampleStructIDL(0.0, 0.0)] * 5
        impatient = Miro.Example(plain_stub._ref, plain_stub._invoker, timeout=0.5)
        with pytest.raises(TIMEOUT):
            impatient.getData()  # waits for a worker
        assert all(t.is_alive() for t in blocked)
    finally:
        release.set()
        for t in blocked:
            t.join(10)
        client.close()
        server.stop()


def test_the_router_beyond_loopback_needs_insecure_and_a_busy_port_is_one_line() -> None:
    from loopback import free_port, run_miro

    refused = run_miro("naming", "--zenoh", "--endpoint", f"tcp://0.0.0.0:{free_port()}")
    assert refused.returncode == 2 and "--insecure" in refused.stderr.splitlines()[-1]
    assert "Traceback" not in refused.stderr
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        taken = run_miro("naming", "--zenoh", "--endpoint", f"tcp://127.0.0.1:{port}",
                         "--log-file", "none")  # fmt: skip
    assert taken.returncode == 1 and "cannot run a Zenoh router" in taken.stderr, taken.stderr
    assert "Traceback" not in taken.stderr and len(taken.stderr.strip().splitlines()) == 1


def test_a_fleet_channel_hears_every_robots_channel_with_the_robot_as_domain(
    naming: NamingProcess,
) -> None:
    from loopback import Recorder, eventually

    from miro_gen import EventChannelFactory, StructuredPushSupplier

    zenoh_options = ("--transport", "zenoh")
    robots = [RunningServer(naming.endpoint, f"robot{i}", *zenoh_options) for i in (1, 2)]
    base = RunningServer(naming.endpoint, "base", *zenoh_options)
    try:
        suppliers = [
            StructuredPushSupplier(EventChannelFactory(r.server).create_channel("EventChannel"))
            for r in robots
        ]
        fleet = Recorder(base.server.resolve_channel("*/EventChannel"))
        fleet.set_subscriptions([("*", "ExampleEvent")])
        eventually(lambda: all(s.has_subscribers("ExampleEvent") for s in suppliers))
        for n, s in enumerate(suppliers):
            s.push("ExampleEvent", Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(n, n)))
        eventually(lambda: len(fleet.events) == 2)
        assert {e.domain_name for e in fleet.events} == {"robot1", "robot2"}
        with pytest.raises(ValueError, match="consumers only"):
            StructuredPushSupplier(base.server.resolve_channel("*/EventChannel"))
    finally:
        for r in (base, *robots):
            r.stop()


def test_the_base_records_every_robots_events_from_the_fleet_channel(
    naming: NamingProcess, tmp_path: Path
) -> None:
    from eventlog_helpers import miro, proc, stop
    from loopback import run_miro

    env = service_env(MIRO_TRANSPORT="zenoh")
    hosts = [proc("channel_host.py", "--transport", "zenoh", "--naming", naming.endpoint,
                  "-MNC", robot, "EventChannel") for robot in ("robot1", "robot2")]  # fmt: skip
    log = tmp_path / "fleet.mcap"
    rec = None
    try:
        for h in hosts:
            assert h.stdout is not None and h.stdout.readline().strip() == "READY"
        rec = miro("log", "record", "--naming", naming.endpoint, "--channel", "*/EventChannel",
                   "-o", str(log), env=env)  # fmt: skip
        assert rec.stderr is not None and rec.stderr.readline().startswith("recording ")
        for robot in ("robot1", "robot2"):
            sup = proc("event_supplier.py", "--transport", "zenoh", "--naming", naming.endpoint,
                       "-MNC", robot, "EventChannel", "20", "5")  # fmt: skip
            out, err = sup.communicate(timeout=60)
            assert sup.returncode == 0 and "DONE" in out, err
        stop(rec)
        rec = None
        info = run_miro("log", "info", str(log))
        assert info.returncode == 0, info.stderr
        counts = {line.split()[0]: line.split()[2] for line in info.stdout.splitlines()
                  if "events" in line and "/" in line.split()[0]}  # fmt: skip
        assert counts == {"robot1/ExampleEvent": "20", "robot2/ExampleEvent": "20"}, info.stdout
    finally:
        if rec is not None:
            rec.kill()
        for h in hosts:
            h.kill()
            h.wait()


class _Tally(StructuredPushConsumer):
    """A keep-all consumer that marks each event's counter, with some work per event (a
    handler slower than its supplier, which keeps the Zenoh thread waiting for the GIL)."""

    def __init__(self, channel: EventChannel, count: int) -> None:
        super().__init__(channel, depth=KEEP_ALL)
        self.seen = bytearray(count + 1)
        self.last = threading.Event()

    def push_structured_event(self, event: StructuredEvent) -> None:
        n = event.payload.counter
        self.seen[n] += 1
        sum(range(300))  # work
        if n == len(self.seen) - 1:
            self.last.set()


def test_a_keep_all_consumer_loses_none_of_100000_small_events(naming: NamingProcess) -> None:
    """Suppliers put a keep-all consumer's topics with congestion control BLOCK, and its link
    holds what waits by bytes, not frames: a supplier process pushing flat out to a consumer
    that takes longer per event, with a busy process per core beside them, loses nothing on
    the way. (Counts, not times.)"""
    import subprocess
    import sys

    from eventlog_helpers import proc

    count = 100_000
    spin = "import time\nend = time.monotonic() + 60\nwhile time.monotonic() < end: pass"
    busy = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(2)]
    supplier = proc("flood_supplier.py", "--transport", "zenoh", "--naming", naming.endpoint,
                    "-MNC", "flood", "Flood", str(count))  # fmt: skip
    consumer = RunningServer(naming.endpoint, "tally", "--transport", "zenoh")
    try:
        assert supplier.stdout is not None and supplier.stdout.readline().strip() == "READY"
        tally = _Tally(consumer.server.resolve_channel("flood/Flood"), count)
        tally.set_subscriptions([("*", "ExampleEvent")])
        assert tally.last.wait(120), f"the last event never came ({sum(tally.seen)} came)"
        assert supplier.stdout.readline().split()[:2] == ["SENT", str(count)]
        lost = [n for n, k in enumerate(tally.seen) if k != 1]
        assert not lost, f"{len(lost)} events lost or doubled, first {lost[:5]}"
        assert tally.missed == 0 and tally.dropped == 0
    finally:
        for p in (supplier, *busy):
            p.kill()
            p.wait()
        consumer.stop()


def test_a_name_bound_once_its_holder_let_it_go_vanishes_with_its_server() -> None:
    """The second server of a name binds it from its leases' thread once the first is gone (the
    retry path); its liveliness token must come with it, so that when this server is killed in
    turn its name goes at once, not when its lease (two minutes here) ends."""
    import signal
    import subprocess
    import sys

    from loopback import eventually
    from repo_paths import TESTS

    naming = NamingProcess(options=("--zenoh", "--hold", "0"))  # a lapsed name is free at once
    started: list[subprocess.Popen[str]] = []

    def spawn(context: str) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [sys.executable, str(TESTS / "procs" / "named_example.py"), "--transport", "zenoh",
             "--naming", naming.endpoint, "-MNC", context, "shared/Retried"],
            stdout=subprocess.PIPE, text=True, env=service_env(MIRO_TEST_LEASE="120"),
        )  # fmt: skip
        started.append(proc)
        assert proc.stdout is not None and proc.stdout.readline().strip() == "READY"
        return proc

    client = Client(["t", "--transport", "zenoh", "--naming", naming.endpoint])

    def holder() -> str | None:
        return {e.name: e.endpoint for e in client.naming.entries("shared/")}.get("shared/Retried")

    def tokens() -> set[str]:
        replies = client.zenoh.liveliness().get(keys.name_token("*/*", "shared/Retried"))
        found = (keys.name_of_token(str(r.ok.key_expr)) for r in replies if r.ok is not None)
        return {f[0] for f in found if f is not None}

    try:
        first = spawn("robot1")
        second = spawn("robot9")  # another service: it waits for the name
        first_endpoint = holder()
        assert first_endpoint is not None and keys.zid_of(first_endpoint) in tokens()
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        eventually(lambda: holder() not in (None, first_endpoint), 30)
        second_endpoint = holder()
        assert second_endpoint is not None
        eventually(lambda: tokens() == {keys.zid_of(second_endpoint)}, 30)
        second.send_signal(signal.SIGKILL)
        second.wait(10)
        eventually(lambda: holder() is None, 30)  # (long before its 120 s lease ends)
    finally:
        client.close()
        for proc in started:
            proc.kill()
            proc.wait(10)
        naming.stop()


def test_a_robots_channel_hears_the_types_the_fleet_shares_from_every_other_robot(
    naming: NamingProcess, monkeypatch: pytest.MonkeyPatch
) -> None:
    """NotifyMulticast's forwarding: with ExampleEvent of EventChannel shared (MIRO_FLEET_EVENTS),
    a consumer of robot2's own channel hears robot1's ExampleEvents under robot1 as the domain,
    not its other types, and robot2's own events once each."""
    from loopback import Recorder, eventually

    from miro_gen import EventChannelFactory, StructuredPushSupplier

    monkeypatch.setenv("MIRO_FLEET_EVENTS", "EventChannel=ExampleEvent")
    zenoh_options = ("--transport", "zenoh")
    robots = [RunningServer(naming.endpoint, f"robot{i}", *zenoh_options) for i in (1, 2)]
    try:
        channels = [EventChannelFactory(r.server).create_channel("EventChannel") for r in robots]
        suppliers = [StructuredPushSupplier(c) for c in channels]
        own = Recorder(channels[1])  # robot2's own channel
        own.set_subscriptions([("*", "*")])
        assert own.channel.name == "robot2/EventChannel"
        # robot1's supplier counts robot2's consumer for the shared type
        eventually(lambda: suppliers[0].has_subscribers("ExampleEvent"))
        eventually(lambda: suppliers[1].has_subscribers("OtherEvent"))
        for n, s in enumerate(suppliers):
            for type_name in ("OtherEvent", "ExampleEvent"):
                s.push(type_name, Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(n, n)))
        for s in suppliers:  # a last one of each: once both came, none before them is to come
            s.push("ExampleEvent", Miro.ExampleEventIDL(9, Miro.ExampleStructIDL(9, 9)))
        last = {("robot1", 9), ("robot2", 9)}
        eventually(lambda: last <= {(e.domain_name, e.payload.counter) for e in own.events})
        got = sorted((e.domain_name, e.type_name, e.payload.counter) for e in own.events)
        assert got == [
            ("robot1", "ExampleEvent", 0),
            ("robot1", "ExampleEvent", 9),
            ("robot2", "ExampleEvent", 1),
            ("robot2", "ExampleEvent", 9),
            ("robot2", "OtherEvent", 1),
        ]
    finally:
        for r in robots:
            r.stop()


def test_the_shared_types_are_read_with_one_line_errors() -> None:
    from miro_gen.transport.zenoh import fleet

    assert fleet.parse("EventChannel=Odometry, RangeScan;Other=*") == {
        "EventChannel": frozenset({"Odometry", "RangeScan"}),
        "Other": frozenset({"*"}),
    }
    assert fleet.parse(fleet.text_of({"E": frozenset({"B", "A"})})) == {"E": frozenset("AB")}
    for bad in ("EventChannel", "EventChannel=", "robot1/EventChannel=Odometry", "E=a b"):
        with pytest.raises(UsageError, match="MIRO_FLEET_EVENTS: "):
            fleet.parse(bad)
    selectors = fleet.selectors("*/E", b"", frozenset({"T"}))
    assert selectors == [("miro/ev/$*%2FE/*/T", b"")]
    assert fleet.selectors("*/E", topic("robot1", "U"), frozenset({"T"})) == []
    assert fleet.selectors("*/E", b"robot1\0", frozenset({"T"})) == [
        ("miro/ev/$*%2FE/robot1/T", topic("robot1", "T"))
    ]
