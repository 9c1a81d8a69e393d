"""`miro log info` and `miro log echo` on logs written here: rates as periods per second,
topics that match nothing said so, and `miro log info` starting with only what it needs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import Miro
import pytest
from loopback import run_miro, service_env

from miro_gen.eventlog.writer import LogWriter
from miro_gen.transport.events.frames import RawEvent

T0 = 1_700_000_000_000_000_000  # ns


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Five robot1/ExampleEvent 0.1 s apart, one robot2/Other between them."""
    path = tmp_path_factory.mktemp("logs") / "run.mcap"
    h = Miro.ExampleEventIDL._type_hash
    writer = LogWriter(str(path))
    for n in range(5):
        data = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL()).serialize()
        t = T0 + n * 100_000_000
        writer.write([RawEvent("robot1", "ExampleEvent", h, 1, n, t, t, data)], t)
        if n == 2:
            writer.write([RawEvent("robot2", "Other", h, 2, 0, t, t, data)], t + 1)
    writer.finish()
    return path


def test_info_rates_are_periods_over_the_span(log: Path) -> None:
    done = run_miro("log", "info", str(log))
    assert done.returncode == 0, done.stderr
    assert "duration:  0.400 s" in done.stdout
    lines = {line.split()[0]: line for line in done.stdout.splitlines() if "events" in line}
    assert "5 events     10.00 Hz" in lines["robot1/ExampleEvent"]  # 4 periods in 0.4 s
    assert "Hz" not in lines["robot2/Other"]  # one event: no rate


def test_info_imports_no_compiler_transport_or_decoder(log: Path) -> None:
    """What `miro log info` imports is its start-up as a command (bench/bench_logplayer.py):
    a summary needs neither the schema compiler, nor the service options and sockets, nor
    the CDR runtime."""
    code = (
        "import contextlib, io, json, sys\n"
        "from miro_gen.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    status = main.main(['log', 'info', {str(log)!r}])\n"
        "print(json.dumps([status, [m for m in sys.modules if m.startswith('miro_gen.')]]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=service_env(), timeout=60
    )
    assert done.returncode == 0, done.stderr
    status, loaded = json.loads(done.stdout)
    assert status == 0
    heavy = ("miro_gen.compile", "miro_gen.service", "miro_gen.transport", "miro_gen.runtime")
    assert not [m for m in loaded if m.startswith(heavy)], loaded


def test_echo_of_a_topic_the_log_does_not_have(log: Path) -> None:
    done = run_miro("log", "echo", str(log), "nope/*")
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr == (
        f"{log}: no topic matches nope/*; the log's topics: robot1/ExampleEvent, robot2/Other\n"
    )


def test_echo_warns_of_a_pattern_that_matches_nothing_beside_one_that_does(log: Path) -> None:
    done = run_miro("log", "echo", str(log), "robot1/*", "robot9/*", "-n", "2")
    assert done.returncode == 0
    assert len(done.stdout.splitlines()) == 2
    assert done.stderr == f"{log}: warning: no topic matches robot9/*\n"
