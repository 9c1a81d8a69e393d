"""The player window's timeline: one track per topic, each with a check box that takes the
topic in or out of the replay (Miro's Events menu), the density of its events over the logs'
span, the cut shaded and the play position as a line; a click on a track seeks there.

The densities come from the file set's segment counts (eventlog.fileset.density): drawing the
timeline of a large log reads nothing of its data.
"""

from __future__ import annotations

import math

from PySide6.QtCore import QRectF, Qt, Signal
from PySide6.QtGui import QColor, QMouseEvent, QPainter, QPaintEvent, QPen
from PySide6.QtWidgets import (
    QCheckBox,
    QGridLayout,
    QScrollArea,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from miro_gen.eventlog.fileset import TopicInfo, TopicName, topic_text

BUCKETS = 400  # densities are computed in this many spans of the logs' time
ROW_HEIGHT = 22


class Track(QWidget):
    """One topic's events over time (bars), the cut and the position; clicks seek."""

    clicked_at = Signal(object)  # log ns (more than 32 bits)

    def __init__(self, timeline: Timeline, name: TopicName) -> None:
        super().__init__()
        self.timeline = timeline
        self.name = name
        self.counts: list[float] = []
        self.setFixedHeight(ROW_HEIGHT - 4)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.setCursor(Qt.CursorShape.PointingHandCursor)

    def x_of(self, log_ns: int) -> float:
        first, last = self.timeline.span
        return (log_ns - first) / max(1, last - first) * (self.width() - 1)

    def time_at(self, x: float) -> int:
        first, last = self.timeline.span
        return first + round(
            min(max(x, 0.0), self.width() - 1) / max(1, self.width() - 1) * (last - first)
        )

    def mousePressEvent(self, event: QMouseEvent) -> None:
        if event.button() == Qt.MouseButton.LeftButton:
            self.clicked_at.emit(self.time_at(event.position().x()))

    def paintEvent(self, event: QPaintEvent) -> None:
        tl = self.timeline
        p = QPainter(self)
        try:
            h, w = self.height(), self.width()
            excluded = self.name in tl.excluded
            p.fillRect(self.rect(), QColor(245, 245, 245))
            start, end = tl.cut
            if self.counts:
                top = max(self.counts) or 1.0
                colour = QColor(160, 160, 160) if excluded else QColor(40, 110, 190)
                width = w / len(self.counts)
                for i, n in enumerate(self.counts):
                    if n > 0:  # a logarithmic height: a sparse topic is still seen
                        bar = max(2.0, (h - 4) * math.log1p(n) / math.log1p(top))
                        p.fillRect(QRectF(i * width, h - 2 - bar, max(1.0, width), bar), colour)
            outside = QColor(60, 60, 60, 110)  # what the cut leaves out, greyed over
            p.fillRect(QRectF(0, 0, self.x_of(start), h), outside)
            p.fillRect(QRectF(self.x_of(end), 0, w - self.x_of(end), h), outside)
            p.setPen(QPen(QColor(220, 40, 40), 2))
            x = self.x_of(tl.position)
            p.drawLine(round(x), 0, round(x), h)
        finally:
            p.end()


class Timeline(QWidget):
    """The tracks of all topics (`set_topics`), their densities (`set_densities`) and the
    play position and cut (`set_state`)."""

    seek_requested = Signal(object)  # log ns
    exclusion_changed = Signal(object, bool)  # (domain, type), excluded

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.span = (0, 1)
        self.cut = (0, 1)
        self.position = 0
        self.excluded: frozenset[TopicName] = frozenset()
        self.boxes: dict[TopicName, QCheckBox] = {}
        self.tracks: dict[TopicName, Track] = {}
        self._rows = QWidget()
        self._grid = QGridLayout(self._rows)
        self._grid.setContentsMargins(2, 2, 2, 2)
        self._grid.setVerticalSpacing(2)
        self._grid.setColumnStretch(1, 1)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self._rows)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(scroll)

    def set_topics(self, topics: list[TopicInfo], excluded: frozenset[TopicName]) -> None:
        """One row per topic, checked unless excluded."""
        for widget in [*self.boxes.values(), *self.tracks.values()]:
            self._grid.removeWidget(widget)
            widget.hide()
            widget.deleteLater()
        for row in range(len(self.boxes) + 1):
            self._grid.setRowStretch(row, 0)
        self.boxes.clear()
        self.tracks.clear()
        self.excluded = excluded
        for row, info in enumerate(topics):
            box = QCheckBox(f"{topic_text(info.name)} ({info.events})")
            box.setChecked(info.name not in excluded)
            box.setToolTip(", ".join(info.schema_names) or "no schema")
            box.toggled.connect(
                lambda on, name=info.name: self.exclusion_changed.emit(name, not on)
            )
            track = Track(self, info.name)
            track.clicked_at.connect(self.seek_requested)
            self._grid.addWidget(box, row, 0)
            self._grid.addWidget(track, row, 1)
            self._grid.setRowMinimumHeight(row, ROW_HEIGHT)
            self.boxes[info.name] = box
            self.tracks[info.name] = track
        self._grid.setRowStretch(len(topics), 1)

    def set_densities(self, densities: dict[TopicName, list[float]], span: tuple[int, int]) -> None:
        self.span = span if span[1] > span[0] else (span[0], span[0] + 1)
        for name, track in self.tracks.items():
            track.counts = densities.get(name, [])
            track.update()

    def set_excluded(self, excluded: frozenset[TopicName]) -> None:
        self.excluded = excluded
        for name, box in self.boxes.items():
            if box.isChecked() == (name in excluded):
                box.blockSignals(True)
                box.setChecked(name not in excluded)
                box.blockSignals(False)
            self.tracks[name].update()

    def set_state(self, position: int, cut: tuple[int, int]) -> None:
        if (position, cut) != (self.position, self.cut):
            self.position, self.cut = position, cut
            for track in self.tracks.values():
                track.update()
