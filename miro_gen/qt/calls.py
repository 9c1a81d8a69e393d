"""Polled calls from a GUI without freezing it: the call runs on a worker thread, its result
(or its exception) comes back to the GUI thread as a signal.

    runner = CallRunner()
    button.clicked.connect(lambda: runner.call(example.getData, on_result=show, on_error=warn))

Stubs may be called from any thread, so a remote call that takes seconds (or fails with
TRANSIENT after its timeout) leaves the window responsive meanwhile.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from PySide6.QtCore import QCoreApplication, QObject, Qt, Signal

from miro_gen.log import logger

_log = logger("QT")
WORKERS = 4  # calls that may be under way at once; more wait their turn


class PendingCall(QObject):
    """One call under way. `finished(result)` or `failed(exception)` is emitted once, on the
    GUI thread; `done`, `result` and `error` tell the outcome afterwards."""

    finished = Signal(object)
    failed = Signal(object)
    _outcome = Signal(bool, object)

    def __init__(self, name: str, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.name = name
        self.done = False
        self.result: Any = None
        self.error: BaseException | None = None
        self._outcome.connect(self._deliver, Qt.ConnectionType.QueuedConnection)

    def _deliver(self, ok: bool, value: Any) -> None:
        self.done = True
        if ok:
            self.result = value
            self.finished.emit(value)
        else:
            self.error = value
            self.failed.emit(value)


class CallRunner(QObject):
    """Runs calls on a small pool of worker threads for the GUI thread (create it there)."""

    def __init__(self, workers: int = WORKERS, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="miro-qt-call")
        self._pending: set[PendingCall] = set()
        self._lock = threading.Lock()
        self._closed = False
        app = QCoreApplication.instance()
        if app is not None:
            app.aboutToQuit.connect(self.close)

    def call(
        self,
        fn: Callable[..., Any],
        *args: Any,
        on_result: Callable[[Any], object] | None = None,
        on_error: Callable[[BaseException], object] | None = None,
    ) -> PendingCall:
        """Run `fn(*args)` on a worker; `on_result(value)` or `on_error(exception)` then runs
        on the GUI thread. Without `on_error`, a failure is logged (category QT)."""
        if self._closed:
            raise RuntimeError("this CallRunner is closed")
        name = getattr(fn, "__qualname__", repr(fn))
        pending = PendingCall(name)
        if on_result is not None:
            pending.finished.connect(on_result)
        pending.failed.connect(on_error if on_error is not None else self._log_failure(name))
        pending.finished.connect(lambda _: self._forget(pending))
        pending.failed.connect(lambda _: self._forget(pending))
        with self._lock:
            self._pending.add(pending)  # kept alive until its outcome is delivered

        def work() -> None:
            try:
                value = fn(*args)
            except Exception as e:
                pending._outcome.emit(False, e)
            else:
                pending._outcome.emit(True, value)

        self._pool.submit(work)
        return pending

    @staticmethod
    def _log_failure(name: str) -> Callable[[BaseException], None]:
        def log(e: BaseException) -> None:
            _log.warning("%s failed: %s", name, e)

        return log

    def _forget(self, pending: PendingCall) -> None:
        with self._lock:
            self._pending.discard(pending)

    @property
    def pending(self) -> int:
        """Calls whose outcome the GUI has not had yet."""
        with self._lock:
            return len(self._pending)

    def close(self) -> None:
        """Take no more calls; calls under way finish on their workers (not waited for)."""
        self._closed = True
        self._pool.shutdown(wait=False, cancel_futures=True)
