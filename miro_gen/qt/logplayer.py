"""`miro log player`: Miro's LogPlayer window on MCAP logs (its MainForm, FileSet, EventView
and ChannelManager, point by point in docs/LOGS.md).

The window only shows the model and hands it the user's commands: the file set, the cut and
the exclusions are eventlog.fileset's, the play clock and the steps eventlog.player's, the
channels eventlog.routes'. A timer reads the model about 30 times a second (the clock, the
slider, the timeline, the event list, the chosen topic's last event); the player's thread
never touches a widget.

Controls: Play, Pause, Stop (back to the start of the cut), Prev and Next (one event back or
forward), the clock (min:sec.centiseconds from the start of the cut), a time slider and a
per-topic timeline that seek when moved or clicked, a speed dial. Keys: space plays and
pauses, left and right step, shift+left and shift+right seek a 20th of the cut, + and - change
the speed, Home stops.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QAction, QCloseEvent, QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QApplication,
    QDial,
    QDockWidget,
    QFileDialog,
    QGridLayout,
    QHBoxLayout,
    QInputDialog,
    QLabel,
    QLCDNumber,
    QMainWindow,
    QMenu,
    QMessageBox,
    QProgressDialog,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from miro_gen.eventlog.edit import write_selection
from miro_gen.eventlog.fileset import FileSet, TopicInfo, TopicName
from miro_gen.eventlog.logfile import Cancelled
from miro_gen.eventlog.player import MAX_HISTORY, RATES, Player, Row
from miro_gen.eventlog.reader import LogError, Topic
from miro_gen.eventlog.routes import Routes
from miro_gen.eventlog.show import clock_text
from miro_gen.eventlog.types import types_from_schemas
from miro_gen.qt.event_table import EventTable
from miro_gen.qt.inspector import Inspector
from miro_gen.qt.timeline import BUCKETS, Timeline
from miro_gen.runtime import registry

REFRESH_MS = 33
SLIDER_STEPS = 10_000


def clock_digits(log_ns: int, start_ns: int) -> str:
    """min:sec.centiseconds from the start of the cut, as the clock shows it (`02:05.37`)."""
    cs = max(0, log_ns - start_ns) // 10_000_000
    return f"{cs // 6000:02d}:{cs // 100 % 60:02d}.{cs % 100:02d}"


class LogPlayerWindow(QMainWindow):
    """The player window over `player` (and its file set); `routes` are the channels, which
    get the domains of every file opened."""

    def __init__(self, player: Player, routes: Routes | None = None) -> None:
        super().__init__()
        self.player = player
        self.files: FileSet = player.files
        self.routes = routes
        self.warnings: list[str] = []  # every warning shown, for whoever asks (tests)
        self._updating = False
        self._pinned = -1  # the `sent` count when a row was clicked: its event stays shown
        self._error_shown: object = None
        self.setWindowTitle("LogPlayer")
        self._build_controls()
        self._build_docks()
        self._build_menus()
        self._build_keys()
        self.sent_label = QLabel()
        self.channels_label = QLabel()
        self.statusBar().addPermanentWidget(self.channels_label)
        self.statusBar().addPermanentWidget(self.sent_label)
        self.files.listeners.append(self._files_changed)
        self._timer = QTimer(self)
        self._timer.timeout.connect(self.refresh)
        self._timer.start(REFRESH_MS)
        self._files_changed("files")

    # ---- building -------------------------------------------------------------------------------

    def _button(self, text: str, name: str, slot: Callable[[], object]) -> QPushButton:
        button = QPushButton(text)
        button.setObjectName(name)
        button.setMinimumSize(90, 30)
        button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        button.clicked.connect(slot)
        return button

    def _build_controls(self) -> None:
        p = self.player
        self.play_button = self._button("Play", "play", p.play)
        self.stop_button = self._button("Stop", "stop", p.stop)
        self.pause_button = self._button("Pause", "pause", p.pause)
        self.prev_button = self._button("Prev", "prev", p.prev)
        self.next_button = self._button("Next", "next", p.next)
        self.clock = QLCDNumber(8)
        self.clock.setSegmentStyle(QLCDNumber.SegmentStyle.Flat)
        self.clock.setMinimumHeight(34)
        self.date = QLabel()
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setObjectName("time")
        self.slider.setRange(0, SLIDER_STEPS)
        self.slider.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.slider.valueChanged.connect(self._slider_moved)
        self.dial = QDial()
        self.dial.setObjectName("speed")
        self.dial.setRange(0, len(RATES) - 1)
        self.dial.setNotchesVisible(True)
        self.dial.setWrapping(False)
        self.dial.setFixedSize(84, 84)
        self.dial.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.dial.valueChanged.connect(self._dial_turned)
        self.speed_label = QLabel()
        self.speed_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        grid = QGridLayout()
        grid.addWidget(self.play_button, 0, 0)
        grid.addWidget(self.stop_button, 0, 1)
        grid.addWidget(self.pause_button, 0, 2)
        grid.addWidget(self.prev_button, 1, 0)
        grid.addWidget(self.clock, 1, 1)
        grid.addWidget(self.next_button, 1, 2)
        speed = QVBoxLayout()
        speed.addWidget(self.dial)
        speed.addWidget(self.speed_label)
        top = QHBoxLayout()
        top.addLayout(grid)
        top.addLayout(speed)
        top.addStretch(1)
        self.timeline = Timeline()
        self.timeline.seek_requested.connect(self.player.seek)
        self.timeline.exclusion_changed.connect(self.set_excluded)
        central = QWidget()
        layout = QVBoxLayout(central)
        layout.addLayout(top)
        row = QHBoxLayout()
        row.addWidget(self.slider, 1)
        row.addWidget(self.date)
        layout.addLayout(row)
        layout.addWidget(self.timeline, 1)
        self.setCentralWidget(central)

    def _build_docks(self) -> None:
        self.events = EventTable()
        self.events.event_clicked.connect(self._row_clicked)
        self.events_dock = QDockWidget("Event View", self)
        self.events_dock.setObjectName("events")
        self.events_dock.setWidget(self.events)
        self.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, self.events_dock)
        self.inspector = Inspector(self.files)
        self.inspector_dock = QDockWidget("Event", self)
        self.inspector_dock.setObjectName("event")
        self.inspector_dock.setWidget(self.inspector)
        self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, self.inspector_dock)
        self.resizeDocks([self.inspector_dock], [560], Qt.Orientation.Horizontal)
        self.resizeDocks([self.events_dock], [240], Qt.Orientation.Vertical)

    def _build_menus(self) -> None:
        bar = self.menuBar()
        file = bar.addMenu("&File")
        self.open_action = file.addAction("&Open...", self.choose_files)
        self.open_action.setShortcut(QKeySequence.StandardKey.Open)
        self.close_menu = file.addMenu("&Close")
        self.save_action = file.addAction("Save cut &as...", lambda: self.save_cut_as())
        self.save_action.setShortcut(QKeySequence.StandardKey.Save)
        file.addSeparator()
        file.addAction("&Quit", self.close).setShortcut(QKeySequence.StandardKey.Quit)
        edit = bar.addMenu("&Edit")
        self.cut_front_action = edit.addAction("Cut &front", self.cut_front)
        self.cut_back_action = edit.addAction("Cut &back", self.cut_back)
        self.undo_action = edit.addAction("&Undo cut", self.files.undo_cut)
        self.undo_action.setShortcut(QKeySequence.StandardKey.Undo)
        edit.addAction("Undo &all cuts", self.files.undo_all)
        self.events_menu = bar.addMenu("E&vents")
        view = bar.addMenu("&Tools")
        view.addAction(self.events_dock.toggleViewAction())
        view.addAction(self.inspector_dock.toggleViewAction())
        settings = bar.addMenu("&Settings")
        settings.addAction("&History...", self.ask_history)

    def _build_keys(self) -> None:
        p = self.player
        for key, action in (
            (Qt.Key.Key_Space, p.toggle),
            (Qt.Key.Key_Right, p.next),
            (Qt.Key.Key_Left, p.prev),
            (Qt.KeyboardModifier.ShiftModifier | Qt.Key.Key_Right, lambda: p.skip(1)),
            (Qt.KeyboardModifier.ShiftModifier | Qt.Key.Key_Left, lambda: p.skip(-1)),
            (Qt.Key.Key_Plus, lambda: self._faster(1)),
            (Qt.Key.Key_Equal, lambda: self._faster(1)),
            (Qt.Key.Key_Minus, lambda: self._faster(-1)),
            (Qt.Key.Key_Home, p.stop),
        ):
            QShortcut(QKeySequence(key), self).activated.connect(action)

    # ---- the model's changes --------------------------------------------------------------------

    def _files_changed(self, what: str) -> None:
        """The file set changed (on this, the GUI thread): rebuild what shows it."""
        topics = self.files.topics()
        if what == "files":
            self.inspector.set_topics(topics)
            self._build_events_menu(topics)
            self._build_close_menu()
            self.timeline.set_topics(topics, self.files.excluded)
            self.timeline.set_densities(
                self.files.density(BUCKETS, *self.files.span()), self.files.span()
            )
            self._show_channels()
        elif what == "excluded":
            self.timeline.set_excluded(self.files.excluded)
            for action in self.events_menu.findChildren(QAction):
                name = action.data()
                if isinstance(name, tuple) and action.isChecked() == (name in self.files.excluded):
                    action.blockSignals(True)
                    action.setChecked(name not in self.files.excluded)
                    action.blockSignals(False)
        elif what == "cut":
            self.inspector.replot()
        has_files = bool(self.files.files)
        for w in (self.play_button, self.stop_button, self.pause_button, self.prev_button):
            w.setEnabled(has_files)
        for other in (self.next_button, self.slider, self.dial, self.save_action):
            other.setEnabled(has_files)
        self.undo_action.setEnabled(self.files.can_undo)
        self.refresh()

    def _build_events_menu(self, topics: list[TopicInfo]) -> None:
        """Miro's Events menu: a submenu per domain, a checkable entry per type."""
        self.events_menu.clear()
        menus: dict[str, QMenu] = {}
        for info in topics:
            domain, type_name = info.name
            menu = menus.get(domain)
            if menu is None:
                menu = menus[domain] = self.events_menu.addMenu(domain)
            action = menu.addAction(type_name)
            action.setCheckable(True)
            action.setChecked(info.name not in self.files.excluded)
            action.setData(info.name)
            action.toggled.connect(self._excluder(info.name))
        self.events_menu.setEnabled(bool(topics))

    def _excluder(self, name: TopicName) -> Callable[[bool], None]:
        def toggled(checked: bool) -> None:
            self.set_excluded(name, not checked)

        return toggled

    def _build_close_menu(self) -> None:
        self.close_menu.clear()
        for path in self.files.paths():
            self.close_menu.addAction(path, functools.partial(self.close_file, path))
        self.close_menu.setEnabled(bool(self.files.files))

    def _show_channels(self) -> None:
        if self.routes is None:
            return
        shown = sorted({r.channel for r in self.routes.routes.values()})
        self.channels_label.setText("into " + ", ".join(shown) if shown else "no channel")

    # ---- the timer ------------------------------------------------------------------------------

    def refresh(self) -> None:
        """Show where the player is (the timer calls it; so may anyone)."""
        p, files = self.player, self.files
        start, end = files.cut
        now = min(max(p.log_now(), start), end)
        text = clock_digits(now, start)
        self.clock.setDigitCount(max(8, len(text)))
        self.clock.display(text)
        self.date.setText(clock_text(now) if files.files else "")
        if not self.slider.isSliderDown():
            self._updating = True
            self.slider.setValue(round((now - start) / max(1, end - start) * SLIDER_STEPS))
            self._updating = False
        self.timeline.set_state(now, (start, end))
        self._show_rate()
        self.events.show_rows(p.history.rows(), p.history.version, self._pinned != p.sent)
        if self._pinned != p.sent and self.inspector.topic is not None:
            latest = p.latest.get(self.inspector.topic)
            if latest is not None:
                self.inspector.show_event(latest)
        state = "playing" if p.playing else "at the end" if p.at_end else "paused"
        self.sent_label.setText(f"{p.sent} events sent, {state}")
        if p.error is not None and p.error is not self._error_shown:
            self._error_shown = p.error
            where = getattr(p.error, "path", "")
            self.warn(f"{where}: {p.error}" if where else str(p.error))

    def _show_rate(self) -> None:
        rate, pace = self.player.rate, self.player.pace()  # pace: held back by a consumer
        self.speed_label.setText(f"x{rate:g}" if pace is None else f"x{pace:.2g} (held back)")
        index = min(range(len(RATES)), key=lambda i: abs(RATES[i] - rate))
        if self.dial.value() != index and not self.dial.isSliderDown():
            self._updating = True
            self.dial.setValue(index)
            self._updating = False

    # ---- the user's commands --------------------------------------------------------------------

    def _slider_moved(self, value: int) -> None:
        if self._updating:
            return
        start, end = self.files.cut
        self.player.seek(start + (end - start) * value // SLIDER_STEPS)

    def _dial_turned(self, index: int) -> None:
        if not self._updating:
            self.player.set_rate(RATES[index])
            self._show_rate()

    def _faster(self, steps: int) -> None:
        self.player.faster(steps)
        self._show_rate()

    def _row_clicked(self, row: object) -> None:
        """A row of the event list: the player moves to its event, which the inspector shows
        (read again: the list keeps no payloads)."""
        if isinstance(row, Row):
            self.player.seek_to(row)
            self._pinned = self.player.sent
            try:
                event = next(self.files.forward(row.key), None)
            except LogError as e:
                self.warn(str(e))
                return
            if event is not None and event.key == row.key:
                self.inspector.show_event(event)

    def set_excluded(self, name: TopicName, excluded: bool) -> None:
        """Take a topic out of the replay (or back in), as its check box or menu entry does."""
        self.files.exclude(name, excluded)

    def cut_front(self) -> None:
        if not self.files.cut_front(self.player.log_now()):
            self.statusBar().showMessage("nothing would be left after the cut", 5000)

    def cut_back(self) -> None:
        if not self.files.cut_back(self.player.log_now()):
            self.statusBar().showMessage("nothing would be left after the cut", 5000)

    def ask_history(self) -> None:
        n, ok = QInputDialog.getInt(
            self,
            "LogPlayer",
            "Events in the event list:",
            self.player.history.length,
            1,
            MAX_HISTORY,
            10,
        )
        if ok:
            self.set_history(n)

    def set_history(self, length: int) -> None:
        self.player.history.set_length(length)
        self.refresh()

    def warn(self, text: str) -> None:
        """Say `text` in the status bar and in a box that does not block."""
        self.warnings.append(text)
        self.statusBar().showMessage(text, 10_000)
        box = QMessageBox(QMessageBox.Icon.Warning, "LogPlayer", text, parent=self)
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()

    # ---- files ----------------------------------------------------------------------------------

    def choose_files(self) -> None:
        paths, _ = QFileDialog.getOpenFileNames(
            self, "Open logs", "", "MCAP logs (*.mcap);;All (*)"
        )
        if paths:
            self.open_files(paths)

    def open_files(self, paths: list[str]) -> int:
        """Open logs into the set (a progress dialog while one without an index is read
        through); how many were opened. Problems are warnings."""
        opened = 0
        for path in paths:
            progress = _ScanProgress(self, path)
            try:
                log = self.files.add(path, progress)
            except Cancelled:
                self.statusBar().showMessage(f"{path}: not opened (cancelled)", 5000)
                continue
            except LogError as e:
                self.warn(f"{path}: {e}")
                continue
            finally:
                progress.close()
            opened += 1
            self.statusBar().showMessage(f"opened {path}: {log.count} events", 5000)
            self._make_decodable(path, list(log.topics.values()))
            for text in [*log.warnings, *([log.fault] if log.fault else [])]:
                self.warn(f"{path}: {text}")
        if self.routes is not None:
            for problem in self.routes.connect(self.files.domains()):
                self.warn(problem)
            self._show_channels()
        return opened

    def _make_decodable(self, path: str, topics: list[Topic]) -> None:
        """Compile the schemas of types not generated here (a log from another project), as
        `miro log echo` does, so that their events show decoded."""
        missing = [
            t
            for t in topics
            if t.schema_encoding == "omgidl" and t.type_hash and registry.find(t.type_hash) is None
        ]
        if missing:
            why = types_from_schemas([t.schema.decode("utf-8", "replace") for t in missing])
            if why is not None:
                names = ", ".join(sorted({t.topic for t in missing}))
                self.warn(f"{path}: cannot decode {names}: {why}")

    def close_file(self, path: str) -> None:
        self.files.remove(path)
        self.statusBar().showMessage(f"closed {path}", 5000)

    def save_cut_as(self, path: str | None = None) -> int | None:
        """Write the cut, less the excluded topics, to a new log (asks where, without
        `path`); how many events, None when not written."""
        if path is None:
            path, _ = QFileDialog.getSaveFileName(self, "Save the cut as", "", "MCAP logs (*.mcap)")
            if not path:
                return None
            if not os.path.splitext(path)[1]:
                path += ".mcap"
        if os.path.realpath(path) in {os.path.realpath(p) for p in self.files.paths()}:
            self.warn(f"{path} is open here: save the cut to another file")
            return None
        start, end = self.files.cut
        box = QProgressDialog(f"Writing {path}", "Cancel", 0, max(1, self.files.count), self)
        box.setWindowModality(Qt.WindowModality.WindowModal)
        box.setMinimumDuration(500)

        def progress(written: int) -> bool:
            box.setValue(min(written, box.maximum()))
            QApplication.processEvents()
            return not box.wasCanceled()

        excluded = self.files.excluded
        try:
            n = write_selection(self.files, path, start, end, lambda t: t not in excluded, progress)
        except Cancelled:
            self.statusBar().showMessage("not saved (cancelled)", 5000)
            return None
        except LogError as e:
            self.warn(str(e))
            return None
        finally:
            box.close()
        self.statusBar().showMessage(f"saved {n} events to {path}", 10_000)
        return n

    def closeEvent(self, event: QCloseEvent) -> None:
        self._timer.stop()
        self.player.pause()
        super().closeEvent(event)


class _ScanProgress:
    """The progress dialog of a file read through (shown once the scan reports progress)."""

    def __init__(self, parent: QWidget, path: str) -> None:
        self.parent = parent
        self.path = path
        self.dialog: QProgressDialog | None = None

    def __call__(self, fraction: float) -> bool:
        if self.dialog is None:
            text = f"Reading {self.path} (it has no index)"
            self.dialog = QProgressDialog(text, "Cancel", 0, 1000, self.parent)
            self.dialog.setWindowModality(Qt.WindowModality.WindowModal)
            self.dialog.setMinimumDuration(0)
        self.dialog.setValue(round(fraction * 1000))
        QApplication.processEvents()
        return not self.dialog.wasCanceled()

    def close(self) -> None:
        if self.dialog is not None:
            self.dialog.close()
