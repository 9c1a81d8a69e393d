"""The event viewer (the manual's qtEventImu, for any event type): subscribes to one type of
event and shows its fields live, with a plot of one numeric field over time, and the image
when the events hold one (a camera's: see miro_gen.qt.images).

    python services/event_viewer.py TYPE [--domain D] [--channel NAME] [--field PATH]
        [--span S] [--import MODULE]... [--screenshot FILE [--after N]] [--duration S]
        [common options]

Click a numeric field to plot it instead. The payloads are decoded with the generated types
of the packages imported (the project's `Miro` always; more with --import). --screenshot
saves the window as a PNG once N events have been shown and quits (with
QT_QPA_PLATFORM=offscreen it needs no display); --duration quits after S seconds.
"""

from __future__ import annotations

import importlib
import sys
import time
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro  # noqa: F401 - the project's event types, for decoding
import MiroNaming
from miro_gen import Server, StructuredEvent, SystemException
from miro_gen.service.options import service_parser

try:
    from miro_gen.qt import QtEventBridge, Subscription
    from miro_gen.qt.app import application, no_display
    from miro_gen.qt.fields import FieldError, get_field, is_number, leaves
    from miro_gen.qt.images import find_image, to_qimage
    from miro_gen.qt.widgets import FieldsView, ImageView, PlotWidget
    from PySide6.QtCore import QTimer, Signal
    from PySide6.QtWidgets import QLabel, QMainWindow, QSplitter, QVBoxLayout, QWidget
except ImportError as e:  # PySide6 missing (or a system library Qt needs)
    hint = "" if "miro-gen[qt]" in str(e) else ": pip install miro-gen[qt]"
    print(f"event_viewer: {e}{hint}", file=sys.stderr)
    sys.exit(1)

RETRY_MS = 1000  # how often to look for a channel that is not bound yet


class ViewerWindow(QMainWindow):
    """A status line, the fields of the latest event, and the plot of one field."""

    event_shown = Signal(int)  # how many events have been shown so far

    def __init__(
        self,
        bridge: QtEventBridge,
        type_name: str,
        domain: str = "*",
        channel: str = "EventChannel",
        field: str | None = None,
        span: float = 30.0,
    ) -> None:
        super().__init__()
        self.bridge = bridge
        self.type_name = type_name
        self.domain = domain
        self.channel_name = channel
        self.field = field
        self.subscription: Subscription | None = None
        self.shown = 0
        self.last_event: StructuredEvent | None = None
        self._rate = (time.monotonic(), 0, 0.0)  # when, received then, events a second
        self.setWindowTitle(f"Miro events: {domain}/{type_name}")
        self.status = QLabel("starting")
        self.fields = FieldsView()
        self.plot = PlotWidget(span=span)
        self.image = ImageView()
        self.image.hide()  # until an event holds an image
        self.fields.field_chosen.connect(self.choose_field)
        split = QSplitter()
        split.addWidget(self.fields)
        split.addWidget(self.plot)
        split.addWidget(self.image)
        split.setSizes([300, 400, 400])
        body = QWidget()
        layout = QVBoxLayout(body)
        layout.addWidget(self.status)
        layout.addWidget(split, 1)
        self.setCentralWidget(body)
        self.resize(760, 420)
        self._retry = QTimer(self)
        self._retry.setSingleShot(True)
        self._retry.timeout.connect(self.subscribe)
        self._tick = QTimer(self)
        self._tick.timeout.connect(self._update_status)
        self._tick.start(1000)

    def subscribe(self) -> None:
        """Subscribe once the channel is bound; until then say so and look again."""
        try:
            channel = self.bridge.channel(self.channel_name)
        except MiroNaming.NotFound:
            self.status.setText(f"waiting for event channel {self.channel_name} to be bound")
            self._retry.start(RETRY_MS)
            return
        except SystemException as e:
            self.status.setText(f"cannot reach the naming service: {e}")
            self._retry.start(RETRY_MS)
            return
        self.subscription = self.bridge.subscribe([(self.domain, self.type_name)], channel)
        self.subscription.received.connect(self.show_event)
        self.status.setText(f"listening to {self.domain}/{self.type_name} on {channel.name}")

    def show_event(self, event: StructuredEvent) -> None:
        payload = event.payload
        self.last_event = event
        self.shown += 1
        self.fields.show_payload(payload)
        image = find_image(payload)
        if image is not None:
            shown = to_qimage(image)
            caption = f"{image.path}: {image.width}x{image.height} {image.encoding or '?'}"
            self.image.show_image(shown, caption if shown else f"{caption}: cannot show it")
            self.image.show()
        if self.field is None:  # the first numeric field, until the user picks another
            self.field = next((p for p, v in leaves(payload) if is_number(v)), None)
            self.plot.title = self.field or "(no numeric field)"
        if self.field is not None:
            try:
                value = get_field(payload, self.field)
            except (FieldError, ValueError) as e:
                self.plot.title = f"{self.field}: {e}"
                self.plot.update()
            else:
                self.plot.title = f"{event.type_name} {self.field}"
                if is_number(value):
                    self.plot.add(float(value), event.stamp)
        self.event_shown.emit(self.shown)

    def choose_field(self, path: str) -> None:
        self.field = path
        self.plot.clear()
        self.plot.title = path

    def _update_status(self) -> None:
        sub = self.subscription
        if sub is not None and self.last_event is None and sub.consumer.undecodable:
            self.status.setText(
                f"{sub.consumer.undecodable} {self.type_name} events of a type no imported "
                "generated module has: --import its package"
            )
        if sub is None or self.last_event is None:
            return
        then, received_then, _ = self._rate
        now, received = time.monotonic(), sub.consumer.received
        rate = (received - received_then) / max(now - then, 1e-6)
        self._rate = (now, received, rate)
        e = self.last_event
        self.status.setText(
            f"{e.domain_name}/{e.type_name} #{e.seq}: {received} received ({rate:.1f}/s), "
            f"{self.shown} shown, {sub.consumer.missed} missed on the way"
        )


def main(argv: list[str] | None = None) -> int:
    server = Server(sys.argv if argv is None else argv)  # takes the common options out
    p = service_parser("event_viewer", __doc__.split("\n\n")[0])
    p.add_argument("type", help="the event type name (ExampleEvent, Gps, Position, Imu, ...)")
    p.add_argument("--domain", default="*", help="the supplier's naming context (default any)")
    p.add_argument("--channel", default="EventChannel", help="event channel (EventChannel)")
    p.add_argument("--field", help="the numeric field to plot (data.a, point.x, ...)")
    p.add_argument("--span", type=float, default=30.0, help="seconds the plot shows (30)")
    p.add_argument("--import", dest="imports", action="append", default=[], metavar="MODULE")
    p.add_argument("--screenshot", type=Path, help="save the window as PNG, then quit")
    p.add_argument("--after", type=int, default=10, help="events shown before --screenshot")
    p.add_argument("--duration", type=float, help="quit after this many seconds")
    args = p.parse_args(server.argv[1:])
    if args.span <= 0:
        p.error("--span must be more than 0 seconds")
    for module in args.imports:
        try:
            importlib.import_module(module)
        except ImportError as e:
            p.error(f"cannot import {module}: {e}")
    problem = no_display()
    if problem is not None:
        print(f"event_viewer: {problem}", file=sys.stderr)
        return 1
    app = application("event_viewer")
    window = ViewerWindow(
        QtEventBridge(server), args.type, args.domain, args.channel, args.field, args.span
    )
    bridge = window.bridge
    bridge.stop_with(window)
    saved: list[Path] = []

    def screenshot() -> None:
        if args.screenshot is not None and not saved:
            saved.append(args.screenshot)
            if not window.grab().save(str(args.screenshot), "PNG"):
                print(f"event_viewer: cannot write {args.screenshot}", file=sys.stderr)
            app.quit()

    if args.screenshot is not None:

        def maybe_screenshot(shown: int) -> None:
            if shown == args.after:
                QTimer.singleShot(50, screenshot)  # once this event is painted

        window.event_shown.connect(maybe_screenshot)
    if args.duration is not None:
        QTimer.singleShot(int(args.duration * 1000), screenshot if args.screenshot else app.quit)
    window.show()
    window.subscribe()
    bridge.start()
    app.exec()
    bridge.stop()
    print(f"event_viewer: {window.shown} events shown", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "event_viewer")
