"""`miro foxglove` from a browser: a page in headless Chromium (Debian's, driven by
playwright-core) connects to the bridge with the subprotocol foxglove.sdk.v1, subscribes and
shows a live value (tests/foxglove/live.html), as Foxglove's web app would connect to it."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_foxglove_bridge import FOXGLOVE, WAIT, Robot, _skip_reason

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _browser_skip_reason() -> str | None:
    if _skip_reason() is not None:
        return _skip_reason()
    if CHROMIUM is None:
        return "Debian's chromium is not installed (.ci/run installs it)"
    if not (FOXGLOVE / "node_modules" / "playwright-core").is_dir():
        return "playwright-core is not installed: run `npm ci` in tests/foxglove (.ci/run does)"
    return None


pytestmark = pytest.mark.skipif(
    _browser_skip_reason() is not None, reason=str(_browser_skip_reason())
)


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Robot]:
    r = Robot(tmp_path_factory.mktemp("foxbrowser"))
    try:
        yield r
    finally:
        r.stop()


def test_a_browser_page_shows_a_live_value(robot: Robot, tmp_path: Path) -> None:
    assert CHROMIUM is not None
    shot = tmp_path / "live.png"
    done = subprocess.run(
        ["node", str(FOXGLOVE / "browser.mjs"), CHROMIUM, robot.url, "robot1/Pose", "5", str(shot)],
        capture_output=True,
        text=True,
        timeout=WAIT * 2,
        cwd=FOXGLOVE,
    )
    assert done.returncode == 0, done.stderr
    shown = json.loads(done.stdout)
    assert shown["status"] == "open (foxglove.sdk.v1)"
    assert shown["schema"] == "FoxTest::Pose (omgidl/cdr)"
    values = [int(v) for v in shown["values"]]
    assert len(values) == 5 and values == sorted(values)  # live: the value moves on
    assert shot.stat().st_size > 0
