"""Single key presses from the terminal, for the player's pause, step and quit."""

from __future__ import annotations

import contextlib
import os
import select
import sys
import termios
import threading
import tty
from collections.abc import Callable, Iterator


@contextlib.contextmanager
def key_presses(on_key: Callable[[str], object]) -> Iterator[bool]:
    """Call `on_key(char)` from a thread for each key pressed while inside the block; yields
    whether keys are read (stdin is a terminal). The terminal is restored on the way out."""
    if not sys.stdin.isatty():
        yield False
        return
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    stop = threading.Event()

    def read() -> None:
        while not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                data = os.read(fd, 32)
                if not data:
                    return
                for ch in data.decode(errors="replace"):
                    on_key(ch)

    tty.setcbreak(fd)
    thread = threading.Thread(target=read, name="miro-keys", daemon=True)
    thread.start()
    try:
        yield True
    finally:
        stop.set()
        thread.join(1)
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
