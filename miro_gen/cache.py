"""The per-user cache folder of the compilers: the IDL grammar's LALR tables and the compiled
Jinja templates, so that a run does not redo what the previous one did."""

from __future__ import annotations

import os


def cache_dir() -> str | None:
    """`$XDG_CACHE_HOME/miro-gen` (default `~/.cache/miro-gen`), made if need be; None when it
    cannot be written (a cache only saves time)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    folder = os.path.join(base, "miro-gen")
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return None
    return folder if os.access(folder, os.W_OK) else None
