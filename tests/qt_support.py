"""What the Qt tests share: skip (with the reason) when PySide6 cannot be imported, one
offscreen QApplication, and waiting for a condition while Qt processes its events."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import pytest

os.environ["QT_QPA_PLATFORM"] = "offscreen"  # never a real window, with or without a display

try:  # the Qt tests import Qt from here, so that this runs first
    from PySide6.QtCore import QObject, QPoint, Qt, QThread, QTimer, Signal
    from PySide6.QtGui import QCloseEvent, QImage
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication, QFileDialog, QLabel, QPushButton, QWidget
except ImportError as e:  # PySide6 missing, or a system library Qt needs (libEGL, ...)
    pytest.skip(
        f"PySide6 cannot be imported ({e}): pip install miro-gen[qt]", allow_module_level=True
    )


__all__ = [
    "QApplication",
    "QCloseEvent",
    "QFileDialog",
    "QImage",
    "QLabel",
    "QObject",
    "QPoint",
    "QPushButton",
    "QTest",
    "QThread",
    "QTimer",
    "QWidget",
    "Qt",
    "Signal",
    "application",
    "qt_run",
    "qt_wait",
]


def application() -> QApplication:
    """The process's QApplication (offscreen), created on first use."""
    app = QApplication.instance()
    if app is None:
        app = QApplication(["miro-qt-test"])
    assert isinstance(app, QApplication)
    return app


def qt_wait(check: Callable[[], bool], seconds: float = 30) -> None:
    """Process Qt events until check() is true; fail after `seconds` (a guard against a hang,
    not a bound on how long it may take)."""
    app = application()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        app.processEvents()
        if check():
            return
        time.sleep(0.005)
    raise AssertionError("condition not reached in time")


def qt_run(seconds: float) -> None:
    """Process Qt events for `seconds`."""
    app = application()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        app.processEvents()
        time.sleep(0.002)
