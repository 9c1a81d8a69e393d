"""One status line that rewrites itself on a terminal (stderr), and figures for it."""

from __future__ import annotations

import shutil
import sys
from typing import TextIO


def human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"  # pragma: no cover


def bar(fraction: float, width: int = 24) -> str:
    fraction = min(1.0, max(0.0, fraction))
    full = int(fraction * width)
    return "[" + "#" * full + "-" * (width - full) + "]"


class StatusLine:
    """Shows `update(text)` in place on a terminal; silent on anything else (a pipe, a file),
    where only `done(text)` prints, once."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.live = self.stream.isatty()
        self._shown = False

    def update(self, text: str) -> None:
        if not self.live:
            return
        width = shutil.get_terminal_size((100, 20)).columns - 1
        self.stream.write("\r" + text[:width].ljust(width))
        self.stream.flush()
        self._shown = True

    def done(self, text: str) -> None:
        if self._shown:  # over the status line, all of it
            width = shutil.get_terminal_size((100, 20)).columns - 1
            text = "\r" + text.ljust(width)
        self.stream.write(text + "\n")
        self.stream.flush()
        self._shown = False
