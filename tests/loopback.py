"""What the transport's integration tests share: free ports, the environment of the processes
they start, a `miro naming` process, and waiting for a condition."""

from __future__ import annotations

import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zmq
from miro_cli import REPO

from miro_gen import Server, StructuredEvent, StructuredPushConsumer
from miro_gen.transport.events import KEEP_ALL


def _ephemeral_low() -> int:
    """The lowest port the kernel hands out to outgoing connections (and to bind(0))."""
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


_EPHEMERAL_LOW = _ephemeral_low()


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on (now), below the kernel's ephemeral
    range when there is room: a port from bind(0) is one that any process's next connection
    may take as its source port before the test's process binds it ("Address already in
    use", seen on a loaded machine)."""
    for _ in range(50):
        port = random.randrange(10000, _EPHEMERAL_LOW) if _EPHEMERAL_LOW > 11000 else 0
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return int(s.getsockname()[1])
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def service_env(**extra: str) -> dict[str, str]:
    """The environment of a service process run from this checkout (generated code included)."""
    env = dict(os.environ, **extra)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "generated"), str(REPO)])
    return env


class NamingProcess:
    """`miro naming` in a process of its own, serving on 127.0.0.1 (on `port`, or a free one);
    `options` are more of its command line (`--channel NAME`). Its log of owners is a file of
    its own (`log_file`, in a fresh folder unless given), which `restart` keeps."""

    def __init__(
        self, port: int | None = None, options: tuple[str, ...] = (), log_file: str | None = None
    ) -> None:
        self.port = free_port() if port is None else port
        self.endpoint = f"tcp://127.0.0.1:{self.port}"
        self.options = options
        self._folder = None
        if log_file is None:
            self._folder = tempfile.mkdtemp(prefix="miro-naming-")
            log_file = os.path.join(self._folder, "owners.log")
        self.log_file = log_file
        self.proc = self._start()

    def _start(self) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "miro_gen.cli.main",
                "naming",
                "--endpoint",
                self.endpoint,
                "--log-file",
                self.log_file,
                *self.options,
            ],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("naming service at"), line
        return proc

    def restart(self, sig: int = signal.SIGKILL) -> None:
        """Stop it (killed by default) and start it again on the same port and log."""
        self._halt(sig)
        self.proc = self._start()

    def stop(self, sig: int = signal.SIGKILL) -> None:
        self._halt(sig)
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)

    def _halt(self, sig: int) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        self.proc.wait(10)


def run_miro(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    """`miro ARGS` from this checkout, to the end; its exit status and output."""
    return subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", *args],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=timeout,
    )


class RunningServer:
    """A Server (naming context `context`, more common `options`) whose reactor runs in a
    thread of the test."""

    def __init__(self, naming: str, context: str, *options: str) -> None:
        argv = ["t", "--naming", naming, "-MNC", context, *options]
        self.server = Server(argv, context=zmq.Context())
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()

    def stop(self) -> None:
        self.server.shutdown()
        self.thread.join(10)


class Recorder(StructuredPushConsumer):
    """A consumer that keeps what it receives (`events`), taking `delay` s over each, or held
    before each until `gate` is set (at most a minute: a test that forgets it still ends); it
    keeps every event waiting unless given another `depth` (or `latest_only`)."""

    def __init__(
        self,
        *args: object,
        delay: float = 0.0,
        gate: threading.Event | None = None,
        depth: int = KEEP_ALL,
        latest_only: bool = False,
    ) -> None:
        super().__init__(*args, depth=depth, latest_only=latest_only)  # type: ignore[arg-type]
        self.events: list[StructuredEvent] = []
        self.delay = delay
        self.gate = gate
        self.holding = threading.Event()  # set once a delivery waits at the gate

    def push_structured_event(self, event: StructuredEvent) -> None:
        if self.gate is not None and not self.gate.is_set():
            self.holding.set()
            self.gate.wait(60)
        if self.delay:
            time.sleep(self.delay)
        self.events.append(event)


def rss_mb(pid: int) -> float:
    """The resident memory of process `pid`, in MiB."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmRSS for process {pid}")


def alive(pid: int) -> bool:
    """Whether process `pid` still runs: a zombie waiting for its parent does not, and one its
    parent reaped between two looks is gone (so read /proc once, and take "no file" as gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def eventually(
    check: Callable[[], bool], seconds: float = 10, why: Callable[[], str] | None = None
) -> None:
    """Wait until check() is true; fail after `seconds` (a guard against a hang, not a bound on
    how long it may take), saying `why()` when given."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if check():
            return
        time.sleep(0.01)
    raise AssertionError(why() if why is not None else "condition not reached in time")


def dev_shm() -> set[str]:
    """Files of ours in /dev/shm (other programs of the machine keep theirs there)."""
    try:
        return {n for n in os.listdir("/dev/shm") if "miro" in n}
    except OSError:
        return set()
