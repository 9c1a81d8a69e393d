"""The launch's terminal: every child's lines labelled with its name, and a live status table.

Lines from several reader threads are written whole, one at a time. On a terminal the labels
are coloured and a status table (state, pid, restarts, last exit, up time) stays at the bottom:
before a line is written the table is erased, after it the table is drawn again, so output
scrolls above it. Elsewhere (a pipe, a file) there is no table: changes of state are written as
lines of their own, labelled `launch`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import IO

PALETTE = (36, 32, 35, 33, 34, 91, 92, 95, 96, 93)
LAUNCH_LABEL = "launch"
REDRAW_INTERVAL = 0.5  # seconds between redraws of the table when nothing else happens

Row = tuple[str, ...]


class Console:
    """Writes labelled lines to `stream`; `table` (on a terminal) keeps a status table below."""

    def __init__(
        self,
        stream: IO[str],
        labels: list[str],
        colour: bool,
        table: bool = False,
        routine: bool = True,
    ) -> None:
        self.stream = stream
        self.colour = colour
        self.table = table
        self.routine = routine  # show the launch's routine notes (started, up, stopping)
        self.width = max([len(LAUNCH_LABEL), *map(len, labels)])
        self.colours = {label: PALETTE[i % len(PALETTE)] for i, label in enumerate(labels)}
        self.lock = threading.Lock()
        self._rows: Callable[[], list[Row]] | None = None
        self._drawn = 0  # lines of the table on the screen now
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def line(self, label: str, text: str) -> None:
        tag = f"{label:<{self.width}} |"
        if self.colour:
            code = 1 if label == LAUNCH_LABEL else self.colours.get(label, 37)
            tag = f"\033[{code}m{tag}\033[0m"
        with self.lock:
            self._erase()
            self.stream.write(f"{tag} {text}\n")
            self._draw()
            self.stream.flush()

    def note(self, text: str, routine: bool = False) -> None:
        """A line of the launch's own; a `routine` one only when the console shows them."""
        if self.routine or not routine:
            self.line(LAUNCH_LABEL, text)

    def show_table(self, rows: Callable[[], list[Row]]) -> None:
        """Keep the table of `rows()` (a header first) at the bottom until `close()`."""
        if not self.table:
            return
        self._rows = rows
        self._thread = threading.Thread(target=self._redraw_loop, name="launch-table", daemon=True)
        self._thread.start()

    def refresh(self) -> None:
        if self._rows is None:
            return
        with self.lock:
            self._erase()
            self._draw()
            self.stream.flush()

    def close(self) -> None:
        """Draw the table one last time and leave it on the screen."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2)
        self.refresh()
        self._rows = None
        self._drawn = 0

    def _redraw_loop(self) -> None:
        while not self._stop.wait(REDRAW_INTERVAL):
            self.refresh()

    def _erase(self) -> None:
        if self._drawn:
            self.stream.write(f"\033[{self._drawn}F\033[J")
            self._drawn = 0

    def _draw(self) -> None:
        if self._rows is None:
            return
        rows = self._rows()
        text = format_table(rows)
        if self.colour:
            lines = text.split("\n")
            text = "\n".join([f"\033[7m{lines[0]}\033[0m", *lines[1:]])
        self.stream.write(text + "\n")
        self._drawn = len(rows)


def format_table(rows: list[Row]) -> str:
    """Rows as aligned columns."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join(
        "  ".join(cell.ljust(w) for cell, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )


def duration_text(seconds: float) -> str:
    """`42s`, `3m05s`, `2h04m`."""
    s = int(seconds)
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{s % 3600 // 60:02d}m"


def since(t: float | None) -> str:
    return "" if t is None else duration_text(time.monotonic() - t)
