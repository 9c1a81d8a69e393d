"""Without PySide6, `import miro_gen.qt` and the Qt services say what to install (this runs
whether PySide6 is installed or not: it hides it from a child process)."""

from __future__ import annotations

import subprocess
import sys

from loopback import service_env
from miro_cli import REPO

HIDE = "import sys; sys.modules['PySide6'] = None; "


def run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", HIDE + code],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=60,
    )


def test_importing_miro_gen_qt_names_the_extra() -> None:
    out = run("import miro_gen.qt")
    assert out.returncode == 1
    assert out.stderr.strip().splitlines()[-1].startswith("ImportError: miro_gen.qt needs PySide6")
    assert "pip install miro-gen[qt]" in out.stderr


def test_the_qt_services_say_it_in_one_line() -> None:
    for service in ("event_viewer", "qt_panel"):
        path = REPO / "services" / f"{service}.py"
        out = run(f"sys.argv = [{str(path)!r}, 'X']; import runpy; runpy.run_path(sys.argv[0])")
        assert out.returncode == 1
        assert "pip install miro-gen[qt]" in out.stderr and "Traceback" not in out.stderr


def test_the_log_player_window_says_it_in_one_line() -> None:
    out = run("from miro_gen.cli.main import main; raise SystemExit(main(['log', 'player']))")
    assert out.returncode == 1
    assert out.stderr.startswith("miro log player: ") and out.stderr.count("\n") == 1
    assert "pip install miro-gen[qt]" in out.stderr and "Traceback" not in out.stderr
