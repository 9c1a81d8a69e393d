"""`miro demo`: the four examples and an embedded naming service, labelled, stopped cleanly."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from loopback import free_port, run_miro, service_env

DEMO = [sys.executable, "-m", "miro_gen.cli.main", "demo", "--colour", "never"]


def naming() -> list[str]:
    """Where the demo's naming service is to listen: a free port (never 2809 in tests)."""
    return ["--naming", f"tcp://127.0.0.1:{free_port()}"]


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


def test_the_demo_runs_all_four_examples_until_ctrl_c() -> None:
    """The examples' output, labelled, as they run; then one Ctrl-C stops them all and the
    naming service last. (It waits for the output it checks instead of a duration, so that a
    loaded machine only makes it slower.)"""
    address = naming()
    demo = subprocess.Popen(
        [*DEMO, *address, "--period", "0.5"], stdout=subprocess.PIPE, text=True, env=service_env()
    )
    lines: list[str] = []
    try:
        assert demo.stdout is not None
        deadline = time.monotonic() + 120  # only a broken demo takes this long
        for line in demo.stdout:
            lines.append(line.rstrip("\n"))
            received = [x for x in lines if x.startswith("exampleD | Received ExampleEvent #")]
            if len(received) >= 2 or time.monotonic() > deadline:
                break
        assert len(running_examples(address[1])) == 4
        demo.send_signal(signal.SIGINT)
        lines += demo.stdout.read().splitlines()
        assert demo.wait(20) == 0
    finally:
        if demo.poll() is None:  # a failed assertion must not leave the demo running
            demo.send_signal(signal.SIGINT)
            demo.wait(20)
    assert lines[0] == f"naming   | naming service at {address[1]}"
    assert lines[1] == (
        f"naming   | see it from another terminal: miro nslist --naming {address[1]}; "
        f"miro echo '*/ExampleEvent' --channel ExampleEventChannel --naming {address[1]}"
    )
    assert "exampleA | ExampleA is ready" in lines
    assert "exampleB | The object 'ExampleA' has been found in the naming service" in lines
    assert "exampleB | Variables a and b have been set to: 0 and 10" in lines
    assert "exampleB | Retrieved variables a and b are: 1 and 11" in lines
    # exampleC starts first: its first events may find no subscriber yet, and say so
    published = [x for x in lines if re.fullmatch(r"exampleC \| ExampleEvent #\d+ published", x)]
    received = [line for line in lines if line.startswith("exampleD | Received ExampleEvent #")]
    assert published and len(received) >= 2
    n = int(received[0].split("#")[1].split()[0])
    assert received[0].endswith(f"a = {n}, b = {10 + n}")
    assert lines[-1] == "naming   | stopped"
    assert not running_examples(address[1])


def test_the_demo_stops_by_itself_after_its_duration() -> None:
    address = naming()
    result = run_miro(*DEMO[3:], *address, "--duration", "1", timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[-1] == "naming   | stopped"
    assert not running_examples(address[1])


def test_the_demo_listens_where_the_tools_look_when_it_can(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The default naming address when free (here a stand-in for 2809, which tests never
    use), else any free port; the commands it prints say --naming only when needed."""
    from miro_gen.cli import demo

    port = free_port()
    monkeypatch.setattr(demo, "DEFAULT_NAMING", f"tcp://127.0.0.1:{port}")
    assert demo.naming_address(None) == f"tcp://127.0.0.1:{port}"
    assert "--naming" not in demo.commands(f"tcp://127.0.0.1:{port}")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", port))
        taken.listen()
        assert demo.naming_address(None) == "tcp://127.0.0.1:*"
    assert demo.naming_address("iioploc://robot:9000/NameService") == "tcp://robot:9000"
