"""Reusable widgets for Miro GUIs (the manual's §11.2 "widgets library"): a live view of an
event's fields, a plot of one numeric field over time, and an image. Both are plain QWidgets, so Qt
Designer forms can use them ("Promote to...", header `miro_gen.qt.widgets`) once
`miro_gen.qt.designer.load_ui` has registered them with the loader.
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import Any

from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QImage, QPainter, QPaintEvent, QPen, QPolygonF
from PySide6.QtWidgets import QHeaderView, QTreeWidget, QTreeWidgetItem, QWidget

from miro_gen.qt.fields import is_number, leaves, show


class FieldsView(QTreeWidget):
    """Two columns, field and value, for every scalar inside a payload, updated in place.
    Clicking a numeric field emits `field_chosen(path)` (the viewer plots it)."""

    field_chosen = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setColumnCount(2)
        self.setHeaderLabels(["field", "value"])
        self.setRootIsDecorated(False)
        self.setUniformRowHeights(True)
        self.header().setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        self._rows: dict[str, QTreeWidgetItem] = {}
        self._numeric: set[str] = set()
        self.itemClicked.connect(self._clicked)

    def show_payload(self, payload: Any) -> None:
        """Show `payload`'s fields; rows of fields that no longer exist are removed."""
        seen = set()
        for index, (path, value) in enumerate(leaves(payload)):
            seen.add(path)
            item = self._rows.get(path)
            if item is None:
                item = QTreeWidgetItem([path, ""])
                self.insertTopLevelItem(index, item)
                self._rows[path] = item
            item.setText(1, show(value))
            if is_number(value):
                self._numeric.add(path)
        for path in [p for p in self._rows if p not in seen]:
            item = self._rows.pop(path)
            self.takeTopLevelItem(self.indexOfTopLevelItem(item))
            self._numeric.discard(path)

    def clear(self) -> None:
        """No rows (until the next payload)."""
        super().clear()
        self._rows.clear()
        self._numeric.clear()

    def value_text(self, path: str) -> str | None:
        """The text shown for `path` (None if no such row)."""
        item = self._rows.get(path)
        return None if item is None else item.text(1)

    def paths(self) -> list[str]:
        return list(self._rows)

    def _clicked(self, item: QTreeWidgetItem, _column: int) -> None:
        path = item.text(0)
        if path in self._numeric:
            self.field_chosen.emit(path)


class PlotWidget(QWidget):
    """A value over time: the last `span` seconds as a polyline, scaled to its range, with the
    range and the latest value written in the corners. `add(value)` appends a point."""

    def __init__(self, parent: QWidget | None = None, span: float = 30.0) -> None:
        super().__init__(parent)
        self.span = span
        self.title = ""
        self.points: deque[tuple[float, float]] = deque(maxlen=10_000)
        self.setMinimumSize(240, 120)
        self.line_color = QColor(20, 110, 200)

    def add(self, value: float, t: float | None = None) -> None:
        if not is_number(value) or math.isinf(value):
            return
        self.points.append((time.monotonic() if t is None else t, float(value)))
        self.update()

    def clear(self) -> None:
        self.points.clear()
        self.update()

    def paintEvent(self, event: QPaintEvent) -> None:
        p = QPainter(self)
        try:
            p.setRenderHint(QPainter.RenderHint.Antialiasing)
            p.fillRect(self.rect(), QColor(250, 250, 250))
            metrics = p.fontMetrics()
            pad = metrics.height() + 4
            area = QRectF(self.rect()).adjusted(6, pad, -6, -pad)
            p.setPen(QPen(QColor(180, 180, 180)))
            p.drawRect(area)
            p.setPen(QPen(QColor(40, 40, 40)))
            p.drawText(6, metrics.ascent() + 2, self.title or "waiting for values")
            if not self.points:
                return
            now = self.points[-1][0]
            shown = [(t, v) for t, v in self.points if t >= now - self.span]
            low = min(v for _, v in shown)
            high = max(v for _, v in shown)
            if high - low < 1e-12:
                low, high = low - 1, high + 1
            x0 = shown[0][0]  # the values' own time range, up to `span`
            width = max(now - x0, 1e-9)

            def at(t: float, v: float) -> QPointF:
                x = area.left() + (t - x0) / width * area.width()
                y = area.bottom() - (v - low) / (high - low) * area.height()
                return QPointF(x, y)

            p.setPen(QPen(self.line_color, 2))
            p.drawPolyline(QPolygonF([at(t, v) for t, v in shown]))
            p.setPen(QPen(QColor(40, 40, 40)))
            right = Qt.AlignmentFlag.AlignRight
            top = QRectF(0, 0, self.width() - 6, pad - 2)
            p.drawText(top, int(right | Qt.AlignmentFlag.AlignVCenter), f"max {high:g}")
            bottom = QRectF(0, self.height() - pad + 2, self.width() - 6, pad - 2)
            p.drawText(bottom, int(right | Qt.AlignmentFlag.AlignVCenter), f"min {low:g}")
            p.drawText(
                QRectF(6, self.height() - pad + 2, self.width() / 2, pad - 2),
                int(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignVCenter),
                f"latest {shown[-1][1]:g}, over {now - x0:.1f} s",
            )
        finally:
            p.end()


class ImageView(QWidget):
    """An image scaled to fit (keeping its proportions), with a caption above it;
    `show_image(image)` replaces it (None: the caption says why there is none)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.image: QImage | None = None
        self.caption = ""
        self.setMinimumSize(160, 120)

    def show_image(self, image: QImage | None, caption: str = "") -> None:
        self.image, self.caption = image, caption
        self.update()

    def paintEvent(self, event: QPaintEvent) -> None:
        p = QPainter(self)
        try:
            p.fillRect(self.rect(), QColor(30, 30, 30))
            metrics = p.fontMetrics()
            pad = metrics.height() + 4
            p.setPen(QPen(QColor(230, 230, 230)))
            p.drawText(6, metrics.ascent() + 2, self.caption or "no image yet")
            if self.image is None or self.image.isNull():
                return
            area = QRectF(self.rect()).adjusted(4, pad, -4, -4)
            keep = Qt.AspectRatioMode.KeepAspectRatio
            size = self.image.size().toSizeF().scaled(area.size(), keep)
            x = area.left() + (area.width() - size.width()) / 2
            y = area.top() + (area.height() - size.height()) / 2
            p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform)
            p.drawImage(QRectF(x, y, size.width(), size.height()), self.image)
        finally:
            p.end()
