"""The player's events leave from the play thread (eventlog.replay: a direct link, its socket
shared with the reactor under a lock, transport.reactor's `register_shared`), not through a
turn of the reactor: they reach a consumer process complete and in order while the player's
reactor is held up; subscriptions that come while the play thread sends reach the supplier;
and a link closed while a thread sends ends the sending without an error, every event counted.
"""

from __future__ import annotations

import threading
from pathlib import Path

import Miro
import zmq
from eventlog_helpers import T0, read_events, write_log
from loopback import Recorder, eventually
from qt_procs import ServiceProcess

from miro_gen import Server
from miro_gen.eventlog.fileset import FileSet
from miro_gen.eventlog.player import Player
from miro_gen.eventlog.replay import ReplaySupplier
from miro_gen.eventlog.routes import Routes
from miro_gen.transport.events import EventChannelFactory

N = 400  # events, 1 ms apart: 0.4 s at 1x


def test_replayed_events_reach_a_consumer_process_while_the_reactor_is_held(
    naming: str, server: Server, tmp_path: Path
) -> None:
    log = write_log(tmp_path / "robotA.mcap", [("robotA", n, n) for n in range(N)])
    routes = Routes(server)
    assert routes.connect(["robotA"]) == []  # hosts robotA/EventChannel
    assert routes.routes["robotA"].supplier.direct
    consumer = ServiceProcess(
        "tests/procs/event_printer.py", "--naming", naming, "-MNC", "robotA", "EventChannel"
    )
    files = FileSet()
    files.add(str(log))
    player = Player(files, routes.send)
    held, release = threading.Event(), threading.Event()

    def hold() -> None:  # a long turn of the player's reactor: nothing else runs on it
        held.set()
        release.wait(60)

    try:
        consumer.wait_line("READY", 30)
        eventually(lambda: routes.subscribed("robotA", "ExampleEvent"), 30)
        server.reactor().call_soon(hold)
        assert held.wait(10)
        player.start()
        player.play()
        assert player.ended.wait(60)
        eventually(
            lambda: len(read_events("\n".join(consumer.lines))) >= N,
            30,
            lambda: f"{len(read_events(chr(10).join(consumer.lines)))} of {N} while held",
        )
        assert not release.is_set()  # all of them arrived with the reactor held
    finally:
        release.set()
        player.close()
        consumer.stop()
        files.close()
    got = read_events("\n".join(consumer.lines))
    assert [(e["domain"], e["seq"]) for e in got] == [("robotA", n) for n in range(N)]
    stamps = [T0 + (n - 1) * 1_000_000 for n in range(N)]  # as recorded (a float of seconds)
    assert all(abs(e["stamp"] - t) < 1000 for e, t in zip(got, stamps, strict=True))
    supplier = routes.routes["robotA"].supplier
    assert (supplier.replayed, supplier.replay_dropped) == (N, 0)


EVENT = Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, -1))
PAYLOAD = EVENT.serialize()


def _push(supplier: ReplaySupplier, seq: int, type_name: str = "Raw") -> None:
    """One event as a player replays it (a logged payload, its stamps)."""
    supplier.push_encoded("robotA", type_name, EVENT._type_hash, 7, seq, seq, seq, PAYLOAD)


def test_subscriptions_reach_a_supplier_whose_thread_keeps_sending(server: Server) -> None:
    channel = EventChannelFactory(server).create_channel("Busy")
    supplier = ReplaySupplier(channel)
    stop = threading.Event()
    pushed = [0]

    def send() -> None:  # the play thread: sends all the time, taking the socket's signals
        while not stop.is_set():
            _push(supplier, pushed[0], f"T{pushed[0] % 8}")
            pushed[0] += 1

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    consumers = []
    try:
        for k in range(8):  # each subscription while the sender sends
            c = Recorder(channel)
            c.set_subscriptions([("robotA", f"T{k}")])
            consumers.append(c)
            eventually(lambda k=k: supplier.has_subscribers_for("robotA", f"T{k}"), 30)  # type: ignore[misc]
        for c in consumers[:4]:
            c.close()
        eventually(
            lambda: not any(supplier.has_subscribers_for("robotA", f"T{k}") for k in range(4)), 30
        )
        assert all(supplier.has_subscribers_for("robotA", f"T{k}") for k in range(4, 8))
        eventually(lambda: all(c.events for c in consumers[4:]), 30)
    finally:
        stop.set()
        sender.join(10)
    assert pushed[0] == supplier.replayed + supplier.replay_dropped


def test_closing_a_link_while_a_thread_sends_counts_every_event(naming: str) -> None:
    s = Server(["replay-test", "--naming", naming, "-MNC", "player"], context=zmq.Context())
    thread = threading.Thread(target=s.run, daemon=True)
    thread.start()
    supplier = ReplaySupplier(EventChannelFactory(s).create_channel("Closing"))
    consumer = Recorder(s.resolve_channel("Closing"))
    consumer.set_subscriptions([("*", "*")])
    eventually(lambda: supplier.has_subscribers_for("robotA", "Raw"), 30)
    failed: list[BaseException] = []
    pushed = [0]
    going, done = threading.Event(), threading.Event()

    def send() -> None:
        try:
            while not done.is_set():
                _push(supplier, pushed[0])
                pushed[0] += 1
                going.set()
        except BaseException as e:  # what the test looks for
            failed.append(e)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        assert going.wait(10)
        s.shutdown()  # the reactor closes the shared socket under its lock, mid-sending
        thread.join(10)
        eventually(lambda: supplier.replay_dropped > 0 or bool(failed), 30)
    finally:
        done.set()
        sender.join(60)
    assert not sender.is_alive() and failed == []
    assert supplier.replayed > 0 and supplier.replay_dropped > 0  # sent, then refused
    assert pushed[0] == supplier.replayed + supplier.replay_dropped
