"""`miro demo`: the four examples and an embedded naming service, labelled, stopped cleanly."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from loopback import run_miro, service_env

DEMO = [sys.executable, "-m", "miro_gen.cli.main", "demo", "--colour", "never"]


def running_examples(endpoint: str) -> list[str]:
    """Command lines of live processes started with this demo's naming endpoint."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            args = cmdline.read_bytes().split(b"\0")
        except OSError:  # it ended meanwhile
            continue
        if endpoint.encode() in args and any(b"example" in a for a in args):
            found.append(b" ".join(args).decode())
    return found


def test_the_demo_runs_all_four_examples_for_its_duration() -> None:
    result = run_miro(*DEMO[3:], "--duration", "3", "--period", "0.5", timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert re.fullmatch(r"naming   \| naming service at tcp://127\.0\.0\.1:\d+", lines[0])
    assert "exampleA | ExampleA is ready" in lines
    assert "exampleB | The object 'ExampleA' has been found in the naming service" in lines
    assert "exampleB | Variables a and b have been set to: 0 and 10" in lines
    assert "exampleB | Retrieved variables a and b are: 1 and 11" in lines
    assert "exampleC | ExampleEvent #0 published" in lines
    received = [line for line in lines if line.startswith("exampleD | Received ExampleEvent #")]
    assert len(received) >= 2
    assert received[0].endswith("a = 0, b = 10")
    assert lines[-1] == "naming   | stopped"
    assert not running_examples(lines[0].rsplit(" ", 1)[1])


def test_ctrl_c_stops_the_examples_and_the_naming_service() -> None:
    demo = subprocess.Popen(DEMO, stdout=subprocess.PIPE, text=True, env=service_env())
    try:
        assert demo.stdout is not None
        endpoint = demo.stdout.readline().rsplit(" ", 1)[1].strip()
        deadline = time.monotonic() + 30
        for line in demo.stdout:
            if line.startswith("exampleD | Received") or time.monotonic() > deadline:
                break
        assert len(running_examples(endpoint)) == 4
        demo.send_signal(signal.SIGINT)
        rest = demo.stdout.read()
        assert demo.wait(20) == 0
        assert rest.rstrip().endswith("naming   | stopped")
        assert not running_examples(endpoint)
    finally:
        if demo.poll() is None:  # a failed assertion must not leave the demo running
            demo.send_signal(signal.SIGINT)
            demo.wait(20)
