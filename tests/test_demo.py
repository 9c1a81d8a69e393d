"""`miro demo`: the four examples and an embedded naming service, labelled, stopped cleanly."""

from __future__ import annotations

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


def test_the_demo_runs_all_four_examples_for_its_duration() -> None:
    address = naming()
    result = run_miro(*DEMO[3:], *address, "--duration", "3", "--period", "0.5", timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == f"naming   | naming service at {address[1]}"
    assert lines[1] == (
        f"naming   | see it from another terminal: miro nslist --naming {address[1]}; "
        f"miro echo '*/ExampleEvent' --channel ExampleEventChannel --naming {address[1]}"
    )
    assert "exampleA | ExampleA is ready" in lines
    assert "exampleB | The object 'ExampleA' has been found in the naming service" in lines
    assert "exampleB | Variables a and b have been set to: 0 and 10" in lines
    assert "exampleB | Retrieved variables a and b are: 1 and 11" in lines
    assert "exampleC | ExampleEvent #0 published" in lines
    received = [line for line in lines if line.startswith("exampleD | Received ExampleEvent #")]
    assert len(received) >= 2
    assert received[0].endswith("a = 0, b = 10")
    assert lines[-1] == "naming   | stopped"
    assert not running_examples(address[1])


def test_ctrl_c_stops_the_examples_and_the_naming_service() -> None:
    demo = subprocess.Popen(DEMO + naming(), stdout=subprocess.PIPE, text=True, env=service_env())
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
