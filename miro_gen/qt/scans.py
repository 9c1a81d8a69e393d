"""Range scans inside event payloads (a laser's, a sonar ring's), found by their fields, and a
view that draws one from above.

A scan is a field named `ranges`, `range`, `distances` or `readings` that holds numbers (a
sequence of them) or sequences of numbers (Miro::RangeScanEventIDL's `range`, one group per
sensor group, drawn one after the other). Where the beams point comes from `angle_min` and
`angle_increment` (ROS's LaserScan) or `start_angle` and `angle_step` beside it, in radians;
without them the beams are spread evenly over 270 degrees when there are more than 361 of
them (a URG or UTM scanner), else over 180 degrees (a SICK LMS), the middle one straight
ahead. Readings that are not finite or not above 0 are left out (Miro's HORIZON_RANGE and
INVALID_RANGE are negative).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass
from typing import Any

from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QPainter, QPaintEvent, QPen, QPolygonF
from PySide6.QtWidgets import QWidget

from miro_gen.qt.fields import field_names, is_number

_RANGES = ("ranges", "range", "distances", "readings")
_STARTS = ("angle_min", "start_angle")
_STEPS = ("angle_increment", "angle_step")
_MAX_DEPTH = 2  # structs searched below the payload


@dataclass(frozen=True)
class ScanField:
    """A scan found in a payload: where it is, its readings and where the first beam points."""

    path: str
    ranges: list[float]
    start: float  # radians, of the first beam (0: straight ahead, counter-clockwise positive)
    step: float  # radians between beams


def find_scan(payload: Any) -> ScanField | None:
    """The first scan in `payload` (in it, or in a struct inside it), or None."""
    return _search(payload, "", 0)


def _search(value: Any, path: str, depth: int) -> ScanField | None:
    names = field_names(value)
    for name in names:
        if name.lower() in _RANGES:
            ranges = _numbers(getattr(value, name))
            if ranges:
                return _scan(value, names, f"{path}.{name}" if path else name, ranges)
    if depth < _MAX_DEPTH:
        for name in names:
            inner = getattr(value, name)
            if field_names(inner):
                found = _search(inner, f"{path}.{name}" if path else name, depth + 1)
                if found is not None:
                    return found
    return None


def _numbers(value: Any) -> list[float]:
    """The readings of a sequence of numbers, or of a sequence of such groups, in order."""
    if isinstance(value, array | list | tuple) and value:
        if all(is_number(v) for v in value):
            return [float(v) for v in value]
        if all(isinstance(v, array | list | tuple) for v in value):
            out: list[float] = []
            for group in value:
                if not all(is_number(v) for v in group):
                    return []
                out.extend(float(v) for v in group)
            return out
    return []


def _scan(value: Any, names: list[str], path: str, ranges: list[float]) -> ScanField:
    by_name = {n.lower(): getattr(value, n) for n in names}
    start = next((by_name[n] for n in _STARTS if is_number(by_name.get(n))), None)
    step = next((by_name[n] for n in _STEPS if is_number(by_name.get(n))), None)
    if start is None or step is None:
        fov = math.radians(270.0 if len(ranges) > 361 else 180.0)
        step = fov / max(1, len(ranges) - 1)
        start = -fov / 2
    return ScanField(path, ranges, float(start), float(step))


class ScanView(QWidget):
    """A scan seen from above, the sensor in the middle looking up the screen, scaled so that
    the farthest reading touches the edge; `show_scan(scan)` replaces it."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.scan: ScanField | None = None
        self.caption = ""
        self.setMinimumSize(160, 120)

    def show_scan(self, scan: ScanField | None, caption: str = "") -> None:
        self.scan, self.caption = scan, caption
        self.update()

    def points(self) -> list[tuple[float, float]]:
        """(x, y) of each valid reading: x to the left, y ahead, in the readings' unit."""
        scan = self.scan
        if scan is None:
            return []
        out = []
        for i, r in enumerate(scan.ranges):
            if math.isfinite(r) and r > 0:
                a = scan.start + i * scan.step
                out.append((r * math.sin(a), r * math.cos(a)))
        return out

    def paintEvent(self, event: QPaintEvent) -> None:
        p = QPainter(self)
        try:
            p.fillRect(self.rect(), QColor(25, 28, 34))
            metrics = p.fontMetrics()
            pad = metrics.height() + 4
            p.setPen(QPen(QColor(230, 230, 230)))
            p.drawText(6, metrics.ascent() + 2, self.caption or "no scan yet")
            points = self.points()
            if not points:
                return
            area = QRectF(self.rect()).adjusted(6, pad, -6, -6)
            reach = max(max(abs(x), abs(y)) for x, y in points) or 1.0
            scale = min(area.width() / 2, area.height() / 2) / reach
            centre = area.center()
            p.setRenderHint(QPainter.RenderHint.Antialiasing)
            p.setPen(QPen(QColor(70, 80, 95), 1, Qt.PenStyle.DotLine))
            for ring in (0.25, 0.5, 0.75, 1.0):
                p.drawEllipse(centre, reach * ring * scale, reach * ring * scale)
            p.setPen(QPen(QColor(90, 200, 120), 3))
            p.drawPoints(
                QPolygonF(
                    [QPointF(centre.x() - x * scale, centre.y() - y * scale) for x, y in points]
                )
            )
            p.setPen(QPen(QColor(240, 90, 80), 2))
            p.drawEllipse(centre, 4, 4)
        finally:
            p.end()
