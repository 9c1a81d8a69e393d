"""What the manual's examples print, and reading a process's lines as they come (shared by the
tests of the examples on one host and across hosts)."""

from __future__ import annotations

import subprocess

MANUAL_OUTPUT = """\
The object 'ExampleA' has been found in the naming service
Variables a and b have been set to: 0 and 10
Retrieved variables a and b are: 1 and 11
Variables a and b have been set to: 2 and 12
Retrieved variables a and b are: 3 and 13
Variables a and b have been set to: 4 and 14
Retrieved variables a and b are: 5 and 15
Variables a and b have been set to: 6 and 16
"""


def read_lines(proc: subprocess.Popen[str], prefix: str, n: int, seconds: float = 20) -> list[str]:
    """The next n lines of proc's output that start with prefix."""
    import selectors

    assert proc.stdout is not None
    out: list[str] = []
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    import time

    end = time.monotonic() + seconds
    while len(out) < n and time.monotonic() < end:
        if sel.select(timeout=0.5):
            line = proc.stdout.readline()
            if not line:
                break
            if line.startswith(prefix):
                out.append(line.rstrip("\n"))
    return out
