"""Helpers for testing services as they run: an in-process naming service, and a service started
as a process of its own whose output a test can wait for. `miro new` scaffolds tests on these.

    with naming_service() as naming, ServiceProcess("services.hello", "--naming", naming) as s:
        s.wait_for("Hello")
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

import zmq

from miro_gen.transport.naming.service import NamingService
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.rpc.invoker import ZmqInvoker


@contextmanager
def naming_service() -> Iterator[str]:
    """A naming service in this process on a free loopback port; its endpoint."""
    reactor = Reactor(zmq.Context())
    service = NamingService(reactor, ZmqInvoker(reactor.context), "tcp://127.0.0.1:*")
    thread = reactor.run_in_thread("miro-naming")
    try:
        yield service.endpoint
    finally:
        reactor.stop()
        thread.join(10)
        service.close()
        reactor.close()


class ServiceProcess:
    """`python -m MODULE ARGS` in `cwd` (default: the current folder, a project whose generated
    code is in `generated/`), its output (stdout and stderr) collected line by line. `wrapper`
    is a command to run it under (`["ip", "netns", "exec", "robot"]`)."""

    def __init__(
        self,
        module: str,
        *args: str,
        cwd: str | Path | None = None,
        wrapper: Sequence[str] = (),
    ) -> None:
        self.cwd = Path(cwd or os.getcwd())
        env = dict(os.environ)
        paths = [str(self.cwd / "generated"), str(self.cwd), env.get("PYTHONPATH", "")]
        env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
        self.proc = subprocess.Popen(
            [*wrapper, sys.executable, "-u", "-m", module, *args],
            cwd=self.cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def output(self) -> str:
        with self._changed:
            return "\n".join(self.lines)

    def wait_for(self, text: str, timeout: float = 20.0, count: int = 1) -> list[str]:
        """The lines containing `text`, once there are `count` of them; AssertionError (with the
        output so far) when they do not come within `timeout` seconds or the process ends."""
        end = time.monotonic() + timeout
        with self._changed:
            while True:
                found = [line for line in self.lines if text in line]
                if len(found) >= count:
                    return found
                left = end - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    raise AssertionError(
                        f"{count} line(s) with {text!r} expected; output:\n" + "\n".join(self.lines)
                    )
                self._changed.wait(min(left, 0.1))

    def stop(self, timeout: float = 10.0) -> int:
        """Interrupt it as Ctrl-C does and wait; its exit status (killed after `timeout`)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(timeout)
        return self.proc.returncode

    def __enter__(self) -> ServiceProcess:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
