"""The manual's examples as separate processes, with the manual's flags and output (§5.1)."""

from __future__ import annotations

import signal
import subprocess
import sys

from loopback import NamingProcess, service_env
from manual_examples import MANUAL_OUTPUT, read_lines
from repo_paths import REPO

SERVICES = REPO / "services"

# §5.1, as printed in the manual.


def test_example_a_and_b_print_what_the_manual_shows() -> None:
    naming = NamingProcess()
    port = naming.port
    nsc = ["-ORBInitRef", f"NameService=iioploc://127.0.0.1:{port}/NameService"]
    a = None
    try:
        a = subprocess.Popen(
            [sys.executable, str(SERVICES / "exampleA.py"), *nsc, "-MLL", "9", "-MLF", "MIRO"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        assert a.stdout is not None and a.stdout.readline().strip() == "ExampleA is ready"
        b = subprocess.run(
            [
                sys.executable,
                str(SERVICES / "exampleB.py"),
                *nsc,
                "-MLL",
                "9",
                "-MLF",
                "MIRO",
                "--count",
                "4",
                "--period",
                "0",
            ],
            capture_output=True,
            text=True,
            env=service_env(),
            timeout=60,
        )
        assert b.returncode == 0, b.stderr
        assert b.stdout.startswith(MANUAL_OUTPUT)
        a.send_signal(signal.SIGINT)
        assert a.wait(10) == 0
        log = a.stderr.read() if a.stderr else ""
        assert "[DEBUG MIRO] setData(0, 10)" in log  # -MLL 9 -MLF MIRO shows the debug lines
        assert "[NOTICE MIRO] bound" in log
    finally:
        if a is not None and a.poll() is None:
            a.kill()
        naming.stop()


def test_example_b_without_example_a_says_so() -> None:
    naming = NamingProcess()
    port = naming.port
    try:
        b = subprocess.run(
            [
                sys.executable,
                str(SERVICES / "exampleB.py"),
                "--naming",
                f"tcp://127.0.0.1:{port}",
                "-MNC",
                "robot1",
                "--count",
                "1",
            ],
            capture_output=True,
            text=True,
            env=service_env(),
            timeout=60,
        )
        assert b.returncode == 1
        assert "robot1/ExampleA is not bound in the naming service" in b.stderr
        assert "Traceback" not in b.stderr
    finally:
        naming.stop()


def test_example_c_publishes_and_example_d_receives() -> None:
    """§5.2: exampleC creates ExampleEventChannel and publishes; exampleD subscribes."""
    naming = NamingProcess()
    port = naming.port
    nsc = ["-ORBInitRef", f"NameService=iioploc://127.0.0.1:{port}/NameService", "-MNC", "robot1"]
    procs: list[subprocess.Popen[str]] = []
    try:
        c = subprocess.Popen(
            [sys.executable, str(SERVICES / "exampleC.py"), *nsc, "0.05"],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        procs.append(c)
        assert read_lines(c, "ExampleC publishes", 1) == [
            "ExampleC publishes ExampleEvent on robot1/ExampleEventChannel every 0.05 s"
        ]
        assert read_lines(c, "ExampleEvent #", 1)[0].endswith("skipped: no subscribers")
        d = subprocess.Popen(
            [sys.executable, str(SERVICES / "exampleD.py"), *nsc],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        procs.append(d)
        got = read_lines(d, "Received ExampleEvent #", 5)
        assert len(got) == 5, got
        counters = [int(line.split("#")[1].split()[0]) for line in got]
        assert counters == list(range(counters[0], counters[0] + 5))  # in order, none lost
        k = counters[0]
        assert got[0] == f"Received ExampleEvent #{k} from robot1: a = {k}, b = {10 + k}"
        for p in procs:
            p.send_signal(signal.SIGINT)
            assert p.wait(10) == 0
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
        naming.stop()
