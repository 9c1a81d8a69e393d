"""No tracebacks where a user meets the edges: one line saying what failed and what to do,
status 1 (2 for a bad command line, 130 after Ctrl-C), signals handled from a service's first
line to the end of its clean-up. Real processes, real signals."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from loopback import NamingProcess, eventually, free_port, run_miro, service_env
from repo_paths import REPO

SERVICES = REPO / "services"
HINT = "is `miro naming` running? see --naming / MIRO_NAMING"


def start(
    script: str, *args: str, ignore_sigint: bool = False, **kw: object
) -> subprocess.Popen[str]:
    preexec: Callable[[], object] | None = None
    if ignore_sigint:  # as a shell starts a background job of a script
        preexec = lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)  # noqa: E731
    return subprocess.Popen(
        [sys.executable, str(SERVICES / script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
        preexec_fn=preexec,
        **kw,  # type: ignore[call-overload]
    )


def run(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(SERVICES / script), *args],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=60,
    )


def nobody() -> str:
    """A naming address where nothing listens."""
    return f"tcp://127.0.0.1:{free_port()}"


def catches_sigterm(pid: int) -> bool:
    """Whether the process has a handler for SIGTERM: miro_gen.lifecycle's, set on its first
    line (Python itself handles only SIGINT)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    return False


def one_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


@pytest.mark.parametrize("script", ["exampleA.py", "exampleC.py", "exampleD.py", "gps_position.py"])
def test_a_server_told_not_to_wait_for_its_naming_service_says_so_in_one_line(
    script: str,
) -> None:
    done = run(script, "--naming", nobody(), "--wait-naming", "0")
    assert done.returncode == 1
    line = one_line(done.stderr)
    assert line.startswith(script.removesuffix(".py") + ": cannot ")
    assert "cannot be reached (connection refused)" in line and line.endswith(HINT)


def test_a_client_without_a_naming_service_says_so_in_one_line() -> None:
    done = run("exampleB.py", "--naming", nobody())
    assert done.returncode == 1
    assert one_line(done.stderr).endswith(HINT)


@pytest.mark.parametrize("script", ["exampleA.py", "gps_position.py"])
def test_a_server_started_before_its_naming_service_waits_for_it(script: str) -> None:
    """Before: TRANSIENT "cannot be reached", status 1. Now, as ROS 1 nodes do for their
    master: one line saying where the naming service is expected and what to start, then the
    server binds when it appears (issue 34)."""
    from miro_gen import Client

    port = free_port()
    endpoint = f"tcp://127.0.0.1:{port}"
    server = start(script, "--naming", endpoint, "-MNC", "early")
    assert server.stderr is not None
    said = server.stderr.readline()
    assert f"the naming service at {endpoint} does not answer" in said, said
    assert "miro naming" in said and "--wait-naming" in said
    naming = NamingProcess(port)
    client = Client(["t", "--naming", endpoint])
    try:
        service = "exampleA" if script == "exampleA.py" else "gps_position"
        eventually(lambda: _bound(client, f"early/_services/{service}"), 60)
        if script == "exampleA.py":
            assert _bound(client, "early/ExampleA")
        # Its names are bound before it runs; a Ctrl-C in between ends it with 130 (as it
        # should): the signal goes once it says it runs.
        assert server.stdout is not None
        ready = server.stdout.readline()
        assert ready.startswith(("ExampleA is ready", "gps_position: Gps events in")), ready
        server.send_signal(signal.SIGINT)
        _, err = server.communicate(timeout=60)
        assert server.returncode == 0, err
        assert "does not answer" not in err and "Traceback" not in err  # said once
    finally:
        client.close()
        naming.stop()
        if server.poll() is None:
            server.kill()


@pytest.mark.parametrize("background", [False, True])
def test_ctrl_c_while_a_server_waits_for_its_naming_service(background: bool) -> None:
    server = start("exampleA.py", "--naming", nobody(), ignore_sigint=background)
    assert server.stderr is not None
    assert "does not answer" in server.stderr.readline()
    server.send_signal(signal.SIGINT)
    _, err = server.communicate(timeout=60)
    assert server.returncode == 130 and "Traceback" not in err, err


def _bound(client: object, name: str) -> bool:
    import MiroNaming

    try:
        client.naming.resolve(name)  # type: ignore[attr-defined]
    except MiroNaming.NotFound:
        return False
    return True


def test_a_name_not_bound_is_one_line(naming: str) -> None:
    done = run("exampleB.py", "--naming", naming, "-MNC", "robot")
    assert done.returncode == 1
    assert one_line(done.stderr) == (
        "exampleB: robot/ExampleA is not bound in the naming service: is its server running? "
        "(`miro nslist` lists what is)"
    )


@pytest.mark.parametrize("script", ["exampleA.py", "exampleB.py", "exampleC.py", "exampleD.py"])
def test_services_parse_their_own_arguments(script: str) -> None:
    helped = run(script, "--help")
    assert helped.returncode == 0 and helped.stdout.startswith("usage: ")
    assert "common options" in helped.stdout and "-MNC NAME" in helped.stdout
    wrong = run(script, "--no-such-option")
    assert wrong.returncode == 2
    assert "unrecognized arguments: --no-such-option" in wrong.stderr
    assert "Traceback" not in wrong.stderr


def test_a_bad_common_option_is_one_line_and_status_2() -> None:
    done = run("exampleA.py", "-MLL", "eleven")
    assert done.returncode == 2
    assert one_line(done.stderr) == "exampleA: -MLL takes a level from 0 to 9, not 'eleven'"


@pytest.mark.parametrize("background", [False, True])
def test_ctrl_c_while_a_service_starts_ends_it_quietly(background: bool) -> None:
    """From its first line on, SIGINT ends a service with status 130 and no traceback; also a
    background job of a shell script, which inherits SIGINT ignored, is not left running."""
    client = start("exampleB.py", "--naming", nobody(), "--wait", "600", ignore_sigint=background)
    eventually(lambda: catches_sigterm(client.pid))
    client.send_signal(signal.SIGINT)
    out, err = client.communicate(timeout=60)
    assert client.returncode == 130, err
    assert err == "" and out == ""


def test_sigterm_while_a_service_waits_is_status_143() -> None:
    client = start("exampleB.py", "--naming", nobody(), "--wait", "600")
    eventually(lambda: catches_sigterm(client.pid))
    client.send_signal(signal.SIGTERM)
    _, err = client.communicate(timeout=60)
    assert client.returncode == 143 and err == ""


def test_repeated_ctrl_c_during_the_clean_up_is_no_traceback(naming: str) -> None:
    server = start("exampleA.py", "--naming", naming)
    assert server.stdout is not None
    assert server.stdout.readline().strip() == "ExampleA is ready"
    for _ in range(20):  # the first stops it, the others come during its clean-up (or later)
        if server.poll() is not None:
            break
        server.send_signal(signal.SIGINT)
    _, err = server.communicate(timeout=60)
    assert server.returncode == 0, err
    assert "Traceback" not in err


def test_a_server_interrupted_while_it_imports_binds_nothing(naming: str) -> None:
    """A signal during the imports (kept, though the shell ignored SIGINT for it) ends the
    service as its main() begins: status 130, nothing bound."""
    from miro_gen import Client

    server = start("exampleA.py", "--naming", naming, "-MNC", "early", ignore_sigint=True)
    eventually(lambda: catches_sigterm(server.pid))
    server.send_signal(signal.SIGINT)
    _, err = server.communicate(timeout=60)
    assert server.returncode == 130 and err == ""
    client = Client(["t", "--naming", naming])
    try:
        assert [e.name for e in client.naming.entries("early/")] == []
    finally:
        client.close()


def test_ctrl_c_while_the_demo_starts(tmp_path: Path) -> None:
    """Ctrl-C during `miro demo`'s start stops what it started, quietly: status 130 (0 once
    every example is up and it runs until Ctrl-C)."""
    env = service_env(MIRO_NAMING=f"tcp://127.0.0.1:{free_port()}")
    demo = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "demo", "--colour", "never"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert demo.stdout is not None
    assert demo.stdout.readline().startswith("naming   | naming service at")
    demo.send_signal(signal.SIGINT)
    out, err = demo.communicate(timeout=60)
    assert "Traceback" not in out + err and "KeyboardInterrupt" not in out + err
    started = "exampleD | ExampleD listens" in out
    assert demo.returncode == (0 if started else 130), out + err
    assert out.rstrip().endswith("naming   | stopped")


def test_miro_nslist_without_a_naming_service_is_one_line() -> None:
    done = run_miro("nslist", "--naming", nobody())
    assert done.returncode == 1
    assert one_line(done.stderr).endswith(HINT)


def test_a_server_interrupted_between_binding_and_running_unbinds(naming: str) -> None:
    """Interrupted after add_to_name_service and before run(): status 130, and its names go at
    once (not when their lease runs out)."""
    from miro_gen import Client

    script = (
        "import sys, time, Miro__POA\n"
        "from miro_gen import Server\n"
        "from miro_gen.lifecycle import run_main\n"
        "class E(Miro__POA.Example):\n"
        "    def setData(self, a, b): pass\n"
        "    def getData(self): return None\n"
        "def main():\n"
        "    server = Server(sys.argv)\n"
        "    server.add_to_name_service(E(), 'Between')\n"
        "    print('bound', flush=True)\n"
        "    time.sleep(600)\n"
        "    server.run()\n"
        "run_main(main, 'between')\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", script, "--naming", naming, "-MNC", "between"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "bound"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err == ""
    client = Client(["t", "--naming", naming])
    try:
        assert client.naming.entries("between/") == []
    finally:
        client.close()


def run_script(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", script, *args],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=60,
    )


@pytest.mark.parametrize(("status", "expected"), [(None, 1), (3, 3)])
def test_a_services_own_actionable_error_is_one_line(status: int | None, expected: int) -> None:
    """A service's own error derived from ActionableError is told as its failures are: one
    line, its status; lifecycle knows nothing of the class."""
    script = (
        "from miro_gen import ActionableError\n"
        "from miro_gen.lifecycle import run_main\n"
        "class NoArm(ActionableError):\n"
        f"    exit_status = {status or 1}\n"
        "def main():\n"
        "    raise NoArm('no arm on /dev/arm0: is it plugged in?')\n"
        "run_main(main, 'arm')\n"
    )
    done = run_script(script)
    assert done.returncode == expected
    assert one_line(done.stderr) == "arm: no arm on /dev/arm0: is it plugged in?"


def test_a_defect_keeps_its_traceback() -> None:
    script = (
        "from miro_gen.lifecycle import run_main\n"
        "def main():\n"
        "    return {}['missing']\n"
        "run_main(main, 'buggy')\n"
    )
    done = run_script(script)
    assert done.returncode == 1
    assert "Traceback" in done.stderr and "KeyError: 'missing'" in done.stderr


def test_what_zeromq_refuses_is_one_line() -> None:
    """A port another socket holds: ZeroMQ's refusal, made actionable by the transport."""
    port = free_port()
    script = (
        "import zmq\n"
        "from miro_gen import Client\n"
        "from miro_gen.lifecycle import run_main\n"
        "def main():\n"
        "    ctx = zmq.Context()\n"
        "    first, second = ctx.socket(zmq.REP), ctx.socket(zmq.REP)\n"
        f"    first.bind('tcp://127.0.0.1:{port}')\n"
        f"    second.bind('tcp://127.0.0.1:{port}')\n"
        "run_main(main, 'twice')\n"
    )
    done = run_script(script)
    assert done.returncode == 1
    line = one_line(done.stderr)
    assert line.startswith("twice: ZeroMQ: Address already in use") and str(port) in line


def test_a_parameter_document_that_does_not_fit_is_told_not_traced(tmp_path: Path) -> None:
    doc = tmp_path / "bad.xml"
    doc.write_text('<config><section name="Robot"><parameter name="Nope"/></section></config>')
    script = (
        "import sys\n"
        "from miro_gen.params import ParamsError\n"
        "from miro_gen.diagnostics import Diagnostic, SourcePos\n"
        "from miro_gen.lifecycle import run_main\n"
        "def main():\n"
        "    raise ParamsError([Diagnostic('error', SourcePos(sys.argv[1], 1, 0), 'no Nope')])\n"
        "run_main(main, 'reader')\n"
    )
    done = run_script(script, str(doc))
    assert done.returncode == 1
    assert one_line(done.stderr) == f"reader: {doc}:1: error: no Nope"


def test_a_stop_that_comes_before_the_reactor_turns_is_not_lost() -> None:
    """Before: a SIGINT or SIGTERM that came while `Server.run()` started (after its switch to
    stopping on a signal, before its reactor's loop) called `shutdown()`, whose stop the
    reactor's `run()` then cleared as it began: the service served on, its Ctrl-C lost (`miro
    foxglove` stopped just after saying it served ran on in 1 of 10 tries at load 18; a
    test's server stopped at once ran on as a daemon thread). Now `run()` returns."""
    import threading

    import zmq

    from miro_gen import Server

    naming = NamingProcess()
    server = Server(["t", "--naming", naming.endpoint, "-MNC", "early"], context=zmq.Context())
    running = threading.Thread(target=server.run, daemon=True)
    try:
        server.shutdown()  # what the signal's handler does, before the reactor turns
        running.start()
        running.join(60)  # (a guard against the hang)
        assert not running.is_alive(), "run() went on serving after shutdown()"
    finally:
        if running.is_alive():
            server.shutdown()
            running.join(10)
        server.close()
        naming.stop()
