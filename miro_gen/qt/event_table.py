"""The player window's event list (Miro's EventView): the last events sent, one row each with
its time stamp, domain, type and what it is; clicking a row moves the player to that event.

A table model over the player's history (eventlog.player.EventHistory), so a long history
(up to its maximum) costs the rows on screen, not a widget per event.
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import QAbstractTableModel, QModelIndex, QPersistentModelIndex, Qt, Signal
from PySide6.QtWidgets import QAbstractItemView, QHeaderView, QTableView, QWidget

from miro_gen.eventlog.player import Row
from miro_gen.eventlog.show import clock_text

COLUMNS = ("time stamp", "domain", "type", "event")
_Index = QModelIndex | QPersistentModelIndex


class EventRows(QAbstractTableModel):
    """Events as rows (`set_rows` replaces them)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.rows: list[Row] = []

    def set_rows(self, rows: list[Row]) -> None:
        self.beginResetModel()
        self.rows = rows
        self.endResetModel()

    def rowCount(self, parent: _Index = QModelIndex()) -> int:  # noqa: B008 - Qt's signature
        return 0 if parent.isValid() else len(self.rows)

    def columnCount(self, parent: _Index = QModelIndex()) -> int:  # noqa: B008
        return 0 if parent.isValid() else len(COLUMNS)

    def data(self, index: _Index, role: int = Qt.ItemDataRole.DisplayRole) -> Any:
        if role != Qt.ItemDataRole.DisplayRole or not index.isValid():
            return None
        event = self.rows[index.row()]
        column = index.column()
        if column == 0:
            return clock_text(event.log_time)
        if column == 1:
            return event.topic.domain
        if column == 2:
            return event.topic.type_name
        what = event.topic.schema_name or "no schema"
        return f"#{event.sequence}  {what}, {event.size} bytes"

    def headerData(
        self, section: int, orientation: Qt.Orientation, role: int = Qt.ItemDataRole.DisplayRole
    ) -> Any:
        if role == Qt.ItemDataRole.DisplayRole and orientation == Qt.Orientation.Horizontal:
            return COLUMNS[section]
        return None


class EventTable(QTableView):
    """The event list; `event_clicked(row)` when a row is clicked."""

    event_clicked = Signal(object)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model_rows = EventRows(self)
        self.setModel(self.model_rows)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.verticalHeader().setVisible(False)
        self.verticalHeader().setDefaultSectionSize(20)
        header = self.horizontalHeader()
        for column in range(3):
            header.setSectionResizeMode(column, QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        self.clicked.connect(self._clicked)
        self._version = -1

    def show_rows(self, rows: list[Row], version: int, follow: bool) -> None:
        """Show `rows` (if `version` is new); `follow` scrolls to the latest."""
        if version == self._version:
            return
        self._version = version
        self.model_rows.set_rows(rows)
        if follow and rows:
            self.scrollToBottom()

    def _clicked(self, index: QModelIndex) -> None:
        if index.isValid() and index.row() < len(self.model_rows.rows):
            self.event_clicked.emit(self.model_rows.rows[index.row()])
