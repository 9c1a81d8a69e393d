"""services/event_viewer.py, offscreen, fed by a real ExampleC process: the fields change live,
the plot fills, a screenshot shows it; and the command line saves one and exits cleanly."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
import zmq
from loopback import service_env
from qt_procs import REPO, ServiceProcess
from qt_support import QImage, application, qt_wait

from miro_gen import Server
from miro_gen.qt import QtEventBridge
from miro_gen.qt.fields import format_path, get_field, leaves, parse_path, show

VIEWER = REPO / "services" / "event_viewer.py"
_spec = importlib.util.spec_from_file_location("event_viewer", VIEWER)
assert _spec is not None and _spec.loader is not None
event_viewer = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(event_viewer)
ViewerWindow = event_viewer.ViewerWindow


@pytest.fixture
def example_c(naming: str) -> Iterator[ServiceProcess]:
    proc = ServiceProcess("services/exampleC.py", "--naming", naming, "-MNC", "robot", "0.02")
    yield proc
    proc.stop()


def distinct_colours(image: QImage) -> int:
    """Colours in a grid of samples of `image` (a blank or one-colour image has 1)."""
    step = 4
    return len(
        {
            image.pixel(x, y)
            for x in range(0, image.width(), step)
            for y in range(0, image.height(), step)
        }
    )


def test_the_viewer_shows_fields_live_and_plots_one(naming: str, example_c: ServiceProcess) -> None:
    application()
    server = Server(["viewer", "--naming", naming, "-MNC", "gui"], context=zmq.Context())
    bridge = QtEventBridge(server)
    window = ViewerWindow(bridge, "ExampleEvent", "robot", "robot/ExampleEventChannel")
    bridge.stop_with(window)
    window.show()
    window.subscribe()  # retries until ExampleC has bound its channel
    bridge.start()
    try:
        qt_wait(lambda: window.fields.value_text("counter") is not None, 60)
        assert window.fields.paths() == ["counter", "data.a", "data.b"]
        first = int(window.fields.value_text("counter") or 0)
        # Ten events shown, at whatever rate the GUI takes them (a flood is coalesced).
        qt_wait(lambda: int(window.fields.value_text("counter") or 0) >= first + 10, 30)
        qt_wait(lambda: len(window.plot.points) >= 10, 30)
        counter = int(window.fields.value_text("counter") or 0)
        assert window.fields.value_text("data.b") is not None
        assert window.field == "counter"  # the first numeric field, until one is chosen
        values = [v for _, v in window.plot.points]
        assert values == sorted(values) and values[-1] <= counter
        window.fields.field_chosen.emit("data.b")  # as a click on the data.b row does
        qt_wait(lambda: len(window.plot.points) >= 5)
        assert all(v >= 10 for _, v in window.plot.points)  # b = 10 + counter
        assert "robot/ExampleEvent" in window.status.text()
        image = window.grab().toImage()
        assert not image.isNull() and image.width() >= 300 and image.height() >= 200
        assert distinct_colours(image) > 10  # text, a line, frames: not a blank window
    finally:
        window.close()
        qt_wait(lambda: not bridge.running, 60)


def test_the_viewer_command_saves_a_screenshot_and_exits(
    naming: str, example_c: ServiceProcess, tmp_path: Path
) -> None:
    shot = tmp_path / "viewer.png"
    args = ["ExampleEvent", "--channel", "robot/ExampleEventChannel", "--field", "data.a"]
    out = subprocess.run(
        [sys.executable, str(VIEWER), *args, "--naming", naming, "--screenshot", str(shot)],
        capture_output=True,
        text=True,
        env=service_env(QT_QPA_PLATFORM="offscreen"),
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    shown = re.search(r"(\d+) events shown", out.stdout)
    assert shown is not None and int(shown.group(1)) >= 10
    image = QImage(str(shot))
    assert not image.isNull() and image.width() >= 300
    assert distinct_colours(image) > 10
    assert "Traceback" not in out.stderr


def test_the_viewer_command_refuses_bad_input_plainly(naming: str) -> None:
    def run(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, str(VIEWER), *args, "--naming", naming],
            capture_output=True,
            text=True,
            env=service_env(**env),
            timeout=30,
        )

    bad_import = run("ExampleEvent", "--import", "no_such_module", QT_QPA_PLATFORM="offscreen")
    assert bad_import.returncode == 2 and "cannot import no_such_module" in bad_import.stderr
    bad_span = run("ExampleEvent", "--span", "0", QT_QPA_PLATFORM="offscreen")
    assert bad_span.returncode == 2 and "--span" in bad_span.stderr
    env = service_env(QT_QPA_PLATFORM="")
    for var in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        env.pop(var, None)
    no_display = subprocess.run(
        [sys.executable, str(VIEWER), "ExampleEvent", "--naming", naming],
        capture_output=True,
        text=True,
        env=env,
        timeout=30,
    )
    assert no_display.returncode == 1 and "no display" in no_display.stderr
    for out in (bad_import, bad_span, no_display):
        assert "Traceback" not in out.stderr


def test_field_paths() -> None:
    event = Miro.ExampleEventIDL(3, Miro.ExampleStructIDL(1.5, -2.0))
    assert list(leaves(event)) == [("counter", 3), ("data.a", 1.5), ("data.b", -2.0)]
    assert get_field(event, "data.b") == -2.0
    assert get_field(event, "data__a") == 1.5  # the spelling of Designer object names
    group = Miro.ExampleGroupIDL(1, [Miro.ExampleStructIDL(float(i), 0.0) for i in range(20)])
    assert get_field(group, "PointList[3].a") == 3.0
    assert parse_path("points[3].x") == ["points", 3, "x"] == parse_path("points__3__x")
    assert format_path(["points", 3, "x"]) == "points[3].x"
    rows = dict(leaves(group))
    assert len(rows) == 2 + 16 * 2  # the number, 16 elements of two fields, and a summary
    assert any(v == "... 4 more" for v in rows.values())
    with pytest.raises(LookupError, match="no field 'c'"):
        get_field(event, "data.c")
    with pytest.raises(LookupError, match="no \\[5\\]"):
        get_field(event, "data[5]")
    with pytest.raises(ValueError):
        parse_path("data.-1")
    assert show(True) == "true" and show(2.50) == "2.5" and show(b"abc") == "3 bytes"
