"""The player window's view of one event: its fields decoded, its image or range scan drawn
when it has one, and a plot of any numeric field over the whole log or the cut.

The event shown is the last one sent of the chosen topic (or a row clicked in the event list).
A plot reads only the segments that hold the topic (eventlog.fileset.series), on a thread of
its own, and keeps the lowest and highest value of each of a few thousand spans of time, so a
million events plot in bounded memory and a spike is never averaged away.
"""

from __future__ import annotations

import threading
from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QSplitter,
    QStackedWidget,
    QVBoxLayout,
    QWidget,
)

from miro_gen.eventlog.fileset import Event, FileSet, TopicInfo, TopicName, topic_text
from miro_gen.qt.fields import get_field, is_number, parse_path
from miro_gen.qt.images import find_image, to_qimage
from miro_gen.qt.scans import ScanView, find_scan
from miro_gen.qt.widgets import FieldsView, ImageView, PlotWidget
from miro_gen.runtime import registry

PLOT_BUCKETS = 2000
OVER = ("over the whole log", "over the cut")


def decode(event: Event) -> tuple[Any, str | None]:
    """(payload, None), or (None, why it cannot be decoded)."""
    cls = registry.find(event.topic.type_hash) if event.topic.type_hash else None
    if cls is None:
        return None, f"{len(event.message.data)} bytes: no generated type here has its type hash"
    try:
        return cls.deserialize(event.message.data), None
    except Exception as e:  # a payload that does not decode as its type: say so, go on
        return None, f"{len(event.message.data)} bytes that do not decode as {cls._type_name}: {e}"


class Inspector(QWidget):
    """The chosen topic's event (`show_event`), its pictures, and plots of its fields."""

    plotted = Signal(object, object)  # (title, [(log ns, value)]), from the plot's thread

    def __init__(self, files: FileSet, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.files = files
        self.topic: TopicName | None = None
        self._names: list[TopicName] = []  # the topic box's entries
        self.shown: Event | None = None
        self.payload: Any = None
        self.plot_path: str | None = None
        self._plot_cancel = threading.Event()
        self.topics = QComboBox()
        self.topics.currentIndexChanged.connect(self._topic_chosen)
        self.caption = QLabel("no event yet")
        self.fields = FieldsView()
        self.fields.field_chosen.connect(self.plot_field)
        self.image = ImageView()
        self.scan = ScanView()
        self.pictures = QStackedWidget()
        nothing = QLabel("no image or range scan in this event")
        nothing.setWordWrap(True)
        nothing.setAlignment(Qt.AlignmentFlag.AlignCenter)
        for view in (nothing, self.image, self.scan):
            self.pictures.addWidget(view)
        self.plot = PlotWidget(span=1.0)
        self.plot.title = "click a numeric field to plot it"
        self.over = QComboBox()
        self.over.addItems(OVER)
        self.over.currentIndexChanged.connect(lambda _: self.replot())
        head = QHBoxLayout()
        head.addWidget(QLabel("topic"))
        head.addWidget(self.topics, 1)
        head.addWidget(QLabel("plot"))
        head.addWidget(self.over)
        split = QSplitter()
        split.addWidget(self.fields)
        split.addWidget(self.pictures)
        split.setSizes([260, 300])  # the picture a little wider than the fields
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(head)
        layout.addWidget(self.caption)
        layout.addWidget(split, 3)
        layout.addWidget(self.plot, 2)
        self.plotted.connect(self._show_plot)

    # ---- the event ------------------------------------------------------------------------------

    def set_topics(self, topics: list[TopicInfo]) -> None:
        names = [t.name for t in topics]
        self.topics.blockSignals(True)
        self.topics.clear()
        self._names = names
        for name in names:
            self.topics.addItem(topic_text(name))
        keep = self.topic if self.topic in names else (names[0] if names else None)
        if keep is not None:
            self.topics.setCurrentIndex(names.index(keep))
        self.topics.blockSignals(False)
        if keep != self.topic:
            self._choose(keep)

    def choose_topic(self, name: TopicName) -> None:
        """Show topic `name` (as the topic box does when it is picked)."""
        if name in self._names:
            self.topics.setCurrentIndex(self._names.index(name))

    def _topic_chosen(self, index: int) -> None:
        self._choose(self._names[index] if 0 <= index < len(self._names) else None)

    def _choose(self, name: TopicName | None) -> None:
        self.topic = name
        self.shown = None
        self.fields.clear()
        self.caption.setText("no event of this topic sent yet")
        self.pictures.setCurrentIndex(0)
        self.replot(clear=True)

    def show_event(self, event: Event) -> None:
        """Show `event` (switching to its topic)."""
        if event.name != self.topic:
            self.choose_topic(event.name)
        if event is self.shown:
            return
        self.shown = event
        payload, why = decode(event)
        self.payload = payload
        what = f"{topic_text(event.name)} #{event.message.sequence}"
        if why is not None:
            self.caption.setText(f"{what}: {why}")
            self.fields.clear()
            self.pictures.setCurrentIndex(0)
            return
        self.caption.setText(f"{what}: {event.topic.schema_name}")
        self.fields.show_payload(payload)
        image = find_image(payload)
        if image is not None:
            self.image.show_image(to_qimage(image), f"{image.path}: {image.width}x{image.height}")
            self.pictures.setCurrentWidget(self.image)
            return
        scan = find_scan(payload)
        if scan is not None:
            self.scan.show_scan(scan, f"{scan.path}: {len(scan.ranges)} readings")
            self.pictures.setCurrentWidget(self.scan)
            return
        self.pictures.setCurrentIndex(0)

    # ---- plots ----------------------------------------------------------------------------------

    def plot_field(self, path: str) -> None:
        """Plot field `path` of the chosen topic over the log or the cut (a thread reads)."""
        self.plot_path = path
        self.replot()

    def replot(self, clear: bool = False) -> None:
        self._plot_cancel.set()
        if clear:
            self.plot_path = None
        name, path = self.topic, self.plot_path
        self.plot.clear()
        if name is None or path is None:
            self.plot.title = "click a numeric field to plot it"
            return
        whole = self.over.currentIndex() == 0
        start, end = self.files.span() if whole else self.files.cut
        title = f"{path} {OVER[self.over.currentIndex()]}"
        self.plot.title = f"{title}: reading..."
        cancel = self._plot_cancel = threading.Event()
        parts = parse_path(path)
        classes: dict[str, Any] = {}

        def value(event: Event) -> float | None:
            h = event.topic.type_hash
            cls = classes.get(h) if h in classes else classes.setdefault(h, registry.find(h))
            if cls is None:
                return None
            try:
                v = get_field(cls.deserialize(event.message.data), parts)
            except Exception:  # a payload that does not decode, a field it lacks: no point
                return None
            return float(v) if is_number(v) else None

        def work() -> None:
            try:
                points = self.files.series(
                    name, value, start, end, PLOT_BUCKETS, lambda _: not cancel.is_set()
                )
            except Exception as e:  # a damaged log: say so in the plot's title
                points, title_text = [], f"{title}: {e}"
            else:
                title_text = title
            if not cancel.is_set():
                self.plotted.emit((title_text, start), points)

        threading.Thread(target=work, name="miro-plot", daemon=True).start()

    def _show_plot(self, head: tuple[str, int], points: list[tuple[int, float]]) -> None:
        title, start = head
        self.plot.clear()
        self.plot.title = f"{title} ({len(points)} points)" if points else f"{title}: no values"
        if points:
            self.plot.span = max(1e-3, (points[-1][0] - start) / 1e9 + 1)
            for t, v in points:
                self.plot.add(v, (t - start) / 1e9)
