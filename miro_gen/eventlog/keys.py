"""Single key presses from the terminal, for the player's pause, steps, seeks and speed.

Keys come as their characters (" ", "s", "+") or, for the keys a terminal sends as escape
sequences, as names: "left", "right", "up", "down", "home", "end", and "shift-left",
"shift-right" (xterm's `ESC [ 1 ; 2 D`, which most terminals send).
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import sys
import termios
import threading
import tty
from collections.abc import Callable, Iterator

_FINAL = {"A": "up", "B": "down", "C": "right", "D": "left", "H": "home", "F": "end"}
_TILDE = {"1": "home", "7": "home", "4": "end", "8": "end"}
_SEQUENCE = re.compile(r"\x1b(?:\[([0-9;]*)([A-Za-z~])|O([A-Za-z]))")


def key_names(text: str) -> Iterator[str]:
    """The keys in what a terminal sent: characters, and names for escape sequences."""
    at = 0
    while at < len(text):
        m = _SEQUENCE.match(text, at)
        if m is None:
            yield "escape" if text[at] == "\x1b" else text[at]
            at += 1
            continue
        at = m.end()
        params, final, ss3 = m.group(1) or "", m.group(2), m.group(3)
        if ss3:
            name = _FINAL.get(ss3)
        elif final == "~":
            name = _TILDE.get(params.split(";")[0])
        else:
            name = _FINAL.get(final)
            if name is not None and params.split(";")[1:] == ["2"]:
                name = "shift-" + name
        if name is not None:
            yield name


@contextlib.contextmanager
def key_presses(on_key: Callable[[str], object]) -> Iterator[bool]:
    """Call `on_key(key)` from a thread for each key pressed while inside the block; yields
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
                data = os.read(fd, 64)
                if not data:
                    return
                for key in key_names(data.decode(errors="replace")):
                    on_key(key)

    tty.setcbreak(fd)
    thread = threading.Thread(target=read, name="miro-keys", daemon=True)
    thread.start()
    try:
        yield True
    finally:
        stop.set()
        thread.join(1)
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
