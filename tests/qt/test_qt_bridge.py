"""QtEventBridge, offscreen, against real supplier processes on loopback: events reach widgets
on the GUI thread, a flood is coalesced and the GUI stays responsive, closing the window stops
the reactor thread."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable, Iterator

import Miro  # noqa: F401 - the event types, for decoding
import MiroNaming
import pytest
import zmq
from qt_procs import ServiceProcess
from qt_support import QCloseEvent, QLabel, QTimer, QWidget, application, qt_run, qt_wait

from miro_gen import Client, Server, StructuredEvent, StructuredPushConsumer
from miro_gen.qt import QtEventBridge, Subscription
from miro_gen.transport.events import EventChannel
from miro_gen.transport.reactor import Reactor

FLOOD = 150_000
FLOODER = "tests/procs/flood_supplier.py"


@pytest.fixture
def bridges(naming: str) -> Iterator[Callable[..., QtEventBridge]]:
    """Makes bridges over fresh GUI-side Servers; stops them all at the end."""
    application()
    made: list[QtEventBridge] = []

    def make(window: QWidget | None = None) -> QtEventBridge:
        server = Server(["gui", "--naming", naming, "-MNC", "gui"], context=zmq.Context())
        bridge = QtEventBridge(server, window=window)
        made.append(bridge)
        return bridge

    yield make
    for b in made:
        assert b.stop()


@pytest.fixture
def services() -> Iterator[Callable[..., ServiceProcess]]:
    started: list[ServiceProcess] = []

    def start(script: str, *args: str) -> ServiceProcess:
        p = ServiceProcess(script, *args)
        started.append(p)
        return p

    yield start
    for p in started:
        p.stop()


def resolved(bridge: QtEventBridge, name: str) -> EventChannel:
    """The channel `name`, once its supplier process has bound it."""
    end = time.monotonic() + 60
    while True:
        try:
            return bridge.channel(name)
        except MiroNaming.NotFound:
            if time.monotonic() > end:
                raise
            time.sleep(0.05)


class Ticker:
    """Counts a flood in the turns of the GUI thread: at each run of a 10 ms timer, how many
    events the subscription's consumer (on the reactor thread) had received by then."""

    def __init__(self, sub: Subscription) -> None:
        self.sub = sub
        self.received: list[int] = [0]
        self.timer = QTimer()
        self.timer.timeout.connect(lambda: self.received.append(sub.consumer.received))
        self.timer.start(10)

    def most_between_turns(self) -> int:
        """The most events that arrived between two turns of the GUI thread (so far)."""
        marks = [*self.received, self.sub.consumer.received]
        return max(b - a for a, b in itertools.pairwise(marks))


def test_events_from_a_supplier_process_reach_the_widget(
    bridges: Callable[..., QtEventBridge], services: Callable[..., ServiceProcess], naming: str
) -> None:
    services("services/exampleC.py", "--naming", naming, "-MNC", "robot", "0.05")
    window = QWidget()
    label = QLabel("waiting", window)
    window.show()
    bridge = bridges(window)
    channel = resolved(bridge, "robot/ExampleEventChannel")
    sub = bridge.subscribe([("robot", "ExampleEvent")], channel)
    other = bridge.subscribe([("*", "ExampleEvent")], channel)
    on_gui_thread: list[bool] = []
    payloads: dict[int, list[object]] = {}

    def show(event: StructuredEvent) -> None:
        on_gui_thread.append(threading.current_thread() is threading.main_thread())
        label.setText(f"#{event.payload.counter} a={event.payload.data.a:g}")
        payloads.setdefault(event.payload.counter, []).append(event.payload)

    sub.received.connect(show)
    other.received.connect(lambda e: payloads.setdefault(e.payload.counter, []).append(e.payload))
    bridge.start()
    qt_wait(lambda: label.text().startswith("#"), 60)
    first = int(label.text()[1:].split()[0])
    qt_wait(lambda: int(label.text()[1:].split()[0]) >= first + 3)  # live, not a one-off
    n = int(label.text()[1:].split()[0])
    assert label.text() == f"#{n} a={n}"
    assert on_gui_thread and all(on_gui_thread)
    # Each subscription gets its own copy of a payload: equal values, distinct objects.
    both = [p for p in payloads.values() if len(p) == 2]
    assert both
    assert all(a == b and a is not b for a, b in both)


def test_a_flood_is_coalesced_to_the_latest_and_the_gui_stays_responsive(
    bridges: Callable[..., QtEventBridge], services: Callable[..., ServiceProcess], naming: str
) -> None:
    supplier = services(FLOODER, "--naming", naming, "-MNC", "f", "F1", str(FLOOD))
    supplier.wait_line("READY")
    bridge = bridges()
    sub = bridge.subscribe([("f", "ExampleEvent")], resolved(bridge, "f/F1"))
    counters: list[int] = []
    sub.received.connect(lambda e: counters.append(e.payload.counter))
    ticker = Ticker(sub)
    bridge.start()
    qt_wait(lambda: bool(counters), 60)
    qt_wait(lambda: supplier.line("SENT") is not None, 60)
    qt_wait(lambda: counters[-1] == FLOOD, 30)  # the final event always arrives
    assert counters == sorted(set(counters))
    assert sub.consumer.received > FLOOD / 10  # a real flood reached this process ...
    assert len(counters) < sub.consumer.received / 10  # ... and the GUI saw a trickle of it
    assert sub.delivered + sub.dropped == sub.consumer.received
    # The GUI kept turning through the flood: never a third of it without a run of its timer
    # (counted in events, not seconds: a load slows both threads of this process together).
    assert ticker.most_between_turns() < sub.consumer.received / 3


def test_a_bounded_queue_keeps_order_and_drops_the_oldest(
    bridges: Callable[..., QtEventBridge], services: Callable[..., ServiceProcess], naming: str
) -> None:
    supplier = services(FLOODER, "--naming", naming, "-MNC", "q", "Q1", str(FLOOD))
    supplier.wait_line("READY")
    bridge = bridges()
    channel = resolved(bridge, "q/Q1")
    sub = bridge.subscribe([("*", "ExampleEvent")], channel, queue=40, max_rate=20.0)
    batches: dict[int, list[int]] = {}  # the events of each delivery

    def received(e: StructuredEvent) -> None:
        batches.setdefault(sub.deliveries, []).append(e.payload.counter)

    sub.received.connect(received)
    bridge.start()
    start = time.monotonic()
    qt_wait(lambda: supplier.line("SENT") is not None, 60)
    qt_wait(lambda: bool(batches) and batches[max(batches)][-1] == FLOOD, 30)
    elapsed = time.monotonic() - start
    counters = [c for n in sorted(batches) for c in batches[n]]
    assert counters == sorted(set(counters))  # in order, none twice
    assert max(len(b) for b in batches.values()) <= 40
    # At most max_rate deliveries a second: a lower bound on the time they took, which a load
    # can only lengthen (0.9: Qt's coarse timers may fire up to 5 % early).
    assert sub.deliveries <= 1 + elapsed * 20 / 0.9
    assert sub.dropped > 0
    assert sub.delivered + sub.dropped == sub.consumer.received


def test_closing_the_window_stops_the_reactor_thread(
    bridges: Callable[..., QtEventBridge], services: Callable[..., ServiceProcess], naming: str
) -> None:
    supplier = services(FLOODER, "--naming", naming, "-MNC", "c", "C1", "100000", "100")
    supplier.wait_line("READY")

    class Window(QWidget):
        refuse = True

        def closeEvent(self, event: QCloseEvent) -> None:
            if self.refuse:
                event.ignore()
            else:
                event.accept()

    window = Window()
    window.show()
    bridge = bridges(window)
    sub: Subscription = bridge.subscribe([("*", "*")], resolved(bridge, "c/C1"))
    got: list[int] = []
    sub.received.connect(lambda e: got.append(e.payload.counter))
    stopped: list[bool] = []
    bridge.stopped.connect(lambda: stopped.append(True))
    bridge.start()
    qt_wait(lambda: bool(got), 60)
    window.close()  # refused: the window stays, and so does the bridge
    qt_run(0.3)
    assert window.isVisible() and bridge.running
    window.refuse = False
    window.close()
    qt_wait(lambda: not bridge.running, 60)
    assert stopped == [True]
    assert not [t for t in threading.enumerate() if t.name == "miro-qt-reactor"]
    assert sub.closed
    seen = len(got)
    qt_run(0.5)
    assert len(got) == seen  # nothing delivered after the stop


def test_a_bridge_over_a_bare_reactor(naming: str, services: Callable[..., ServiceProcess]) -> None:
    """Any reactor will do: here one with no Server, given a channel found by a Client."""
    supplier = services(FLOODER, "--naming", naming, "-MNC", "b", "B1", "100000", "200")
    supplier.wait_line("READY")
    application()
    context = zmq.Context()
    client = Client(["gui", "--naming", naming], context=context)
    entry = client.naming.resolve("b/B1")
    reactor = Reactor(context)
    channel = EventChannel(entry.name, entry.endpoint, bytes(entry.key).decode(), reactor)
    bridge = QtEventBridge(reactor)
    with pytest.raises(TypeError, match="pass channels"):
        bridge.subscribe([("*", "*")], "b/B1")
    sub = bridge.subscribe([("*", "ExampleEvent")], channel)
    got: list[int] = []
    sub.received.connect(lambda e: got.append(e.payload.counter))
    bridge.start()
    qt_wait(lambda: len(got) >= 5, 60)
    assert got == sorted(got)
    assert bridge.stop() and not bridge.running
    reactor.close()  # a bare reactor is its owner's to close
    client.close()


def test_stopping_at_once_after_starting(bridges: Callable[..., QtEventBridge]) -> None:
    """A window closed as soon as it opened: stop() right after start() still stops."""
    bridge = bridges()
    bridge.start()
    assert bridge.stop()  # False had its reactor thread outlived the stop's own timeout
    assert not bridge.running
    assert not [t for t in threading.enumerate() if t.name == "miro-qt-reactor"]


def test_a_consumer_of_your_own_feeds_a_mailbox(
    bridges: Callable[..., QtEventBridge], services: Callable[..., ServiceProcess], naming: str
) -> None:
    supplier = services(FLOODER, "--naming", naming, "-MNC", "m", "M1", str(FLOOD))
    supplier.wait_line("READY")
    bridge = bridges()
    box = bridge.mailbox()  # latest only

    class Mine(StructuredPushConsumer):
        def push_structured_event(self, event: StructuredEvent) -> None:
            box.offer(event.payload.counter, key="counter")

    mine = Mine(resolved(bridge, "m/M1"))
    mine.set_subscriptions([("*", "ExampleEvent")])
    got: list[int] = []
    box.received.connect(got.append)
    bridge.start()
    qt_wait(lambda: supplier.line("SENT") is not None, 60)
    qt_wait(lambda: bool(got) and got[-1] == FLOOD, 10)
    assert got == sorted(set(got)) and len(got) < mine.received / 10
    assert box.delivered + box.dropped == mine.received

    queued = bridge.mailbox(queue=5, max_rate=0)  # and from a thread of your own
    taken: list[int] = []
    queued.received.connect(taken.append)
    feeder = threading.Thread(target=lambda: [queued.offer(n) for n in range(1000)])
    feeder.start()
    feeder.join()
    qt_wait(lambda: bool(taken) and taken[-1] == 999)
    assert taken == sorted(taken) and queued.delivered + queued.dropped == 1000
    with pytest.raises(ValueError):
        bridge.mailbox(queue=0)
