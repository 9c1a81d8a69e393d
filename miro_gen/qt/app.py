"""The QApplication of a Miro GUI service: refuses politely when there is no display, and
quits on Ctrl-C and SIGTERM (Python's signal handlers only run when Python code does, which
a Qt event loop alone never gives them)."""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication


def no_display() -> str | None:
    """Why Qt could not open a window here (None when it can, or when Qt is told where)."""
    if os.environ.get("QT_QPA_PLATFORM") or not sys.platform.startswith("linux"):
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    return "no display (set DISPLAY, or QT_QPA_PLATFORM=offscreen to run without one)"


def application(name: str) -> QApplication:
    """The process's QApplication (made once), which quits on SIGINT and SIGTERM."""
    app = QApplication.instance()
    if not isinstance(app, QApplication):
        app = QApplication([name])

    def quit_now(signum: int, frame: FrameType | None) -> None:
        app.quit()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, quit_now)
    tick = QTimer(app)  # gives Python a turn now and then, so that the handlers run
    tick.timeout.connect(lambda: None)
    tick.start(200)
    return app
