"""CallRunner: polled calls from the GUI thread to a real server process, without blocking it."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator

import Miro
import pytest
import zmq
from qt_procs import ServiceProcess
from qt_support import QPushButton, QTimer, application, qt_wait

from miro_gen import Client, SystemException
from miro_gen.qt import CallRunner


@pytest.fixture
def example(naming: str) -> Iterator[tuple[ServiceProcess, Miro.Example]]:
    """ExampleA's servant in a process of its own (setData(a, b) with a < 0 sleeps -a s)."""
    proc = ServiceProcess("tests/procs/named_example.py", "--naming", naming, "-MNC", "robot")
    try:
        proc.wait_line("READY")
        client = Client(["gui", "--naming", naming], context=zmq.Context())
        yield proc, client.resolve_name("robot/ExampleA", Miro.Example)
        client.close()
    finally:
        proc.stop()


def test_a_slow_call_from_a_button_leaves_the_gui_responsive(
    example: tuple[ServiceProcess, Miro.Example],
) -> None:
    app = application()
    _, stub = example
    runner = CallRunner()
    results: list[tuple[object, bool]] = []

    def on_result(value: object) -> None:
        results.append((value, threading.current_thread() is threading.main_thread()))

    button = QPushButton("set")
    button.clicked.connect(lambda: runner.call(stub.setData, -1.0, 2.0, on_result=on_result))
    turns: list[bool] = []  # at each run of a 10 ms timer on the GUI thread: result yet?
    timer = QTimer()
    timer.timeout.connect(lambda: turns.append(bool(results)))
    timer.start(10)
    start = time.monotonic()
    button.click()  # the server sleeps 1 s in setData
    assert results == [] and runner.pending == 1  # the click returned before the call did
    qt_wait(lambda: bool(results), 10)
    # It did wait for the server: a lower bound, which a load can only lengthen.
    assert time.monotonic() - start >= 0.9
    assert results == [(None, True)]
    # The GUI kept turning while the call was out (a blocked one would run its timer once).
    assert turns.count(False) >= 3
    pending = runner.call(stub.getData)
    qt_wait(lambda: pending.done)
    assert pending.result == Miro.ExampleStructIDL(0.0, 3.0)  # getData adds 1 to each
    assert runner.pending == 0
    runner.close()
    app.processEvents()


def test_a_failed_call_is_delivered_as_an_error_not_raised(
    example: tuple[ServiceProcess, Miro.Example], caplog: pytest.LogCaptureFixture
) -> None:
    application()
    proc, stub = example
    runner = CallRunner()
    errors: list[BaseException] = []
    ok = runner.call(stub.getData)
    qt_wait(lambda: ok.done)
    proc.stop()  # the server is gone: TRANSIENT or COMM_FAILURE, on the GUI thread
    runner.call(stub.getData, on_result=errors.append, on_error=errors.append)
    qt_wait(lambda: bool(errors), 60)
    assert isinstance(errors[0], SystemException)

    def broken() -> None:
        raise ValueError("no such sensor")

    qt_log = logging.getLogger("miro.QT")  # miro's loggers do not propagate to pytest's
    qt_log.addHandler(caplog.handler)
    try:
        call = runner.call(broken)  # nobody handles the failure: it is logged, not raised
        qt_wait(lambda: call.done)
    finally:
        qt_log.removeHandler(caplog.handler)
    assert isinstance(call.error, ValueError)
    assert "broken failed: no such sensor" in caplog.text
    assert "Traceback" not in caplog.text
    runner.close()
    with pytest.raises(RuntimeError):
        runner.call(broken)
