"""Designer forms bound by object name, offscreen, against real ExampleC and ExampleA processes;
and the errors a wrong form gets (named, all at once, no traceback)."""

from __future__ import annotations

import logging
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
import zmq
from loopback import service_env
from qt_procs import REPO, ServiceProcess
from qt_support import QLabel, QPushButton, QWidget, application, qt_wait

from miro_gen import Server
from miro_gen.qt import QtEventBridge
from miro_gen.qt.designer import FormBinding, UiError, load_ui, parse_name, stub_class
from miro_gen.qt.widgets import PlotWidget

FORM = REPO / "services" / "example_panel.ui"
PANEL = REPO / "services" / "qt_panel.py"


@pytest.fixture
def robot(naming: str) -> Iterator[None]:
    """ExampleC (events every 20 ms) and ExampleA (calls), in naming context `robot`."""
    c = ServiceProcess("services/exampleC.py", "--naming", naming, "-MNC", "robot", "0.02")
    a = ServiceProcess("tests/procs/named_example.py", "--naming", naming, "-MNC", "robot")
    try:
        c.wait_line("ExampleC publishes")
        a.wait_line("READY")
        yield
    finally:
        a.stop()
        c.stop()


def form_with(tmp_path: Path, widgets: str) -> Path:
    path = tmp_path / "form.ui"
    path.write_text(
        '<?xml version="1.0"?><ui version="4.0"><widget class="QWidget" name="Form">'
        f'<layout class="QVBoxLayout" name="box">{widgets}</layout></widget></ui>'
    )
    return path


def item(cls: str, name: str) -> str:
    return f'<item><widget class="{cls}" name="{name}"/></item>'


def test_a_designer_form_shows_events_and_makes_calls(naming: str, robot: None) -> None:
    application()
    form = load_ui(FORM)
    server = Server(["panel", "--naming", naming, "-MNC", "robot"], context=zmq.Context())
    bridge = QtEventBridge(server, window=form)
    binding = FormBinding(form, bridge, channel="ExampleEventChannel")
    bound = binding.bind()
    assert "event__ExampleEvent__data__b___2" in bound and "call__ExampleA__getData" in bound
    form.show()
    bridge.start()
    try:
        a = form.findChild(QLabel, "event__ExampleEvent__data__a")
        b = form.findChild(QLabel, "event__ExampleEvent__data__b")
        plot = form.findChild(PlotWidget, "event__ExampleEvent__data__b___2")
        assert a is not None and b is not None and plot is not None
        qt_wait(lambda: a.text() not in ("-", "0"), 60)
        first = float(a.text())
        qt_wait(lambda: float(a.text()) >= first + 5)  # live
        assert float(b.text()) >= 10
        assert len(plot.points) >= 5 and plot.title == "ExampleEvent data.b"

        form.findChild(QWidget, "arg__ExampleA__setData__a").setValue(2.5)  # type: ignore[union-attr]
        form.findChild(QWidget, "arg__ExampleA__setData__b").setValue(-4)  # type: ignore[union-attr]
        setter = form.findChild(QPushButton, "call__ExampleA__setData")
        getter = form.findChild(QPushButton, "call__ExampleA__getData")
        assert setter is not None and getter is not None
        setter.click()
        qt_wait(lambda: binding.runner.pending == 0 and "ExampleA" in binding._stubs)
        getter.click()
        result_a = form.findChild(QLabel, "result__ExampleA__getData__a")
        result_b = form.findChild(QLabel, "result__ExampleA__getData__b")
        assert result_a is not None and result_b is not None
        qt_wait(lambda: result_a.text() == "3.5" and result_b.text() == "-3")  # getData adds 1
        image = form.grab().toImage()
        assert not image.isNull() and image.width() > 300
    finally:
        form.close()
        qt_wait(lambda: not bridge.running, 60)


def test_calls_that_fail_are_shown_in_the_status_line(naming: str, tmp_path: Path) -> None:
    application()
    path = form_with(
        tmp_path,
        item("QPushButton", "call__Nobody__getData")
        + item("QLineEdit", "arg__ExampleA__setData__a")
        + item("QLineEdit", "arg__ExampleA__setData__b")
        + item("QPushButton", "call__ExampleA__setData")
        + item("QLabel", "status"),
    )
    form = load_ui(path)
    server = Server(["panel", "--naming", naming, "-MNC", "gui"], context=zmq.Context())
    bridge = QtEventBridge(server, window=form)
    binding = FormBinding(form, bridge, interfaces={"ExampleA": Miro.Example})
    binding.bind()
    status = form.findChild(QLabel, "status")
    assert status is not None
    button = form.findChild(QPushButton, "call__Nobody__getData")
    assert button is not None
    button.click()  # nothing is bound as Nobody
    qt_wait(lambda: "Nobody" in status.text(), 10)
    form.findChild(QWidget, "arg__ExampleA__setData__a").setText("two")  # type: ignore[union-attr]
    setter = form.findChild(QPushButton, "call__ExampleA__setData")
    assert setter is not None
    setter.click()  # refused before any call: the argument is not a number
    qt_wait(lambda: "'two' is not a float" in status.text(), 60)
    form.close()


def test_a_form_that_asks_the_impossible_is_refused_with_every_reason(
    naming: str, tmp_path: Path
) -> None:
    application()
    path = form_with(
        tmp_path,
        item("QFrame", "event__ExampleEvent__data__a")
        + item("QLabel", "event__ExampleEvent")
        + item("QLabel", "call__ExampleA__getData")
        + item("QPushButton", "call__ExampleA__getDta")
        + item("QPushButton", "call__ExampleA__setData")
        + item("QLabel", "ordinary_label"),
    )
    form = load_ui(path)
    server = Server(["panel", "--naming", naming, "-MNC", "gui"], context=zmq.Context())
    bridge = QtEventBridge(server)
    binding = FormBinding(
        form, bridge, interfaces={"ExampleA": Miro.Example}, source=str(path.name)
    )
    with pytest.raises(UiError) as e:
        binding.bind()
    lines = str(e.value).splitlines()
    assert lines == [
        "form.ui: event__ExampleEvent__data__a: a QFrame cannot show values",
        "form.ui: event__ExampleEvent: names no field "
        "(event__TYPE__FIELD; only a FieldsView shows all)",
        "form.ui: call__ExampleA__getData: a QLabel cannot be clicked: use a button",
        "form.ui: call__ExampleA__getDta: ExampleA is a IDL:Miro/Example:1.0, "
        "which has no operation getDta",
        "form.ui: call__ExampleA__setData: setData takes a: "
        "the form has no widget arg__ExampleA__setData__a",
    ]
    bridge.stop()


def test_names_and_interfaces() -> None:
    assert parse_name("ordinary") is None and parse_name("event") is None
    n = parse_name("event__Scan__points__3__x___2")
    assert n is not None and (n.kind, n.target, n.rest) == ("event", "Scan", "points__3__x")
    n = parse_name("arg__ExampleA__setData__b")
    assert n is not None and (n.target, n.op, n.rest) == ("ExampleA", "setData", "b")
    assert stub_class("IDL:Miro/Example:1.0") is Miro.Example
    assert stub_class("IDL:Nowhere/Nothing:1.0") is None


def test_the_panel_command_refuses_a_bad_form_plainly(naming: str, tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.ui"
    garbage.write_text("this is not XML <")
    for form, message in (
        (tmp_path / "missing.ui", "cannot open"),
        (garbage, "not a Qt Designer form"),
        (form_with(tmp_path, item("QFrame", "event__X__y")), "a QFrame cannot show values"),
    ):
        out = subprocess.run(
            [sys.executable, str(PANEL), str(form), "--naming", naming],
            capture_output=True,
            text=True,
            env=service_env(QT_QPA_PLATFORM="offscreen"),
            timeout=30,
        )
        assert out.returncode == 1, out.stderr
        assert message in out.stderr and "Traceback" not in out.stderr


def test_a_field_that_events_lack_is_reported_once(
    naming: str, robot: None, tmp_path: Path
) -> None:
    application()
    path = form_with(
        tmp_path,
        item("QLabel", "event__ExampleEvent__data__c")
        + item("QLabel", "event__ExampleEvent__counter")
        + item("QLabel", "status"),
    )
    form = load_ui(path)
    server = Server(["panel", "--naming", naming, "-MNC", "robot"], context=zmq.Context())
    bridge = QtEventBridge(server, window=form)
    binding = FormBinding(form, bridge, channel="ExampleEventChannel")
    errors: list[str] = []
    binding.error.connect(errors.append)
    binding.bind()
    form.show()
    bridge.start()
    try:
        counter = form.findChild(QLabel, "event__ExampleEvent__counter")
        status = form.findChild(QLabel, "status")
        assert counter is not None and status is not None
        qt_wait(lambda: counter.text() not in ("", "0"), 60)
        first = int(counter.text())
        qt_wait(lambda: int(counter.text()) >= first + 3)  # the good field goes on
        assert errors == ["event__ExampleEvent__data__c: data has no field 'c' (a, b)"]
        assert status.text() == errors[0]
    finally:
        form.close()
        qt_wait(lambda: not bridge.running, 60)


def test_a_form_promoting_to_an_unknown_widget_loads_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    application()
    path = tmp_path / "promoted.ui"
    path.write_text(
        '<?xml version="1.0"?><ui version="4.0"><widget class="QWidget" name="Form">'
        '<widget class="Gauge" name="gauge"/></widget><customwidgets><customwidget>'
        "<class>Gauge</class><extends>QWidget</extends><header>gauges.h</header>"
        "</customwidget></customwidgets></ui>"
    )
    qt_log = logging.getLogger("miro.QT")  # miro's loggers do not propagate to pytest's
    qt_log.addHandler(caplog.handler)
    try:
        form = load_ui(path)
    finally:
        qt_log.removeHandler(caplog.handler)
    assert form.findChild(QWidget, "gauge") is not None  # made as its base class
    assert "custom widget of the class 'Gauge'" in caplog.text
