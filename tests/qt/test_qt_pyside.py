"""The installed PySide6 is one miro_gen.qt can rely on.

PySide6 6.12.0 on Python 3.11 drops a reference to True at every signal emission (and to None
at every QTimer.singleShot): after enough events the interpreter aborts, at the latest when it
exits ("bool_dealloc: deallocating True or False"). pyproject.toml keeps the `qt` extra below
6.12 for that; this test tells whoever moves the bound whether the new version is sound.
"""

from __future__ import annotations

import sys

from qt_support import QObject, QTimer, Signal, application, qt_run

import miro_gen.qt  # noqa: F401 - the version this checks is the one miro_gen.qt imports

N = 500


class Emitter(QObject):
    signal = Signal(object)  # what Subscription.received and PendingCall.finished are


def test_signals_and_timers_keep_the_reference_counts_of_true_and_none() -> None:
    application()
    received: list[object] = []
    e = Emitter()
    e.signal.connect(received.append)
    true_before, none_before = sys.getrefcount(True), sys.getrefcount(None)
    for n in range(N):
        e.signal.emit(n)
        QTimer.singleShot(0, lambda: None)
    qt_run(0.05)
    assert len(received) == N
    # Other code takes and drops references meanwhile; a leak of one per call shows anyway.
    assert sys.getrefcount(True) > true_before - N // 2, "PySide6 leaks references to True"
    assert sys.getrefcount(None) > none_before - N // 2, "PySide6 leaks references to None"
