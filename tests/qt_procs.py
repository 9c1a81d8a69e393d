"""Service processes for the Qt tests: started from this checkout, their output read by a
thread (so a chatty service never blocks on a full pipe), stopped with SIGTERM."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

from loopback import service_env

REPO = Path(__file__).resolve().parents[1]


class ServiceProcess:
    """`python SCRIPT ARGS` (a path relative to the repository), its stdout lines in `lines`."""

    def __init__(self, script: str, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(REPO / script), *args],
            stdout=subprocess.PIPE,
            text=True,
            env=service_env(),
        )
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def line(self, prefix: str) -> str | None:
        """The first line printed so far that starts with `prefix`."""
        return next((x for x in list(self.lines) if x.startswith(prefix)), None)

    def wait_line(self, prefix: str, seconds: float = 60) -> str:
        """The first line that starts with `prefix`, once printed; fails when the process has
        ended without it (its output read to the end: a process that printed the line and
        exited at once is not taken for one that never printed it) or after `seconds` (a
        guard against a hang)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            found = self.line(prefix)
            if found is not None:
                return found
            if self.proc.poll() is not None and not self._reader.is_alive():
                found = self.line(prefix)  # (what the reader read before it ended)
                if found is not None:
                    return found
                break
            time.sleep(0.01)
        raise AssertionError(f"{prefix!r} not printed; output: {self.lines}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
