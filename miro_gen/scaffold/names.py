"""What a service may be called: the rule `miro new` enforces and `miro run` explains. No heavy
imports: `miro run` checks names before it starts a service."""

from __future__ import annotations

import keyword
import re

NAME = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
MAX_NAME = 20  # characters: the lines the templates make with it stay short enough


def name_problem(name: str) -> str | None:
    """Why `name` cannot be a service's name (None: it can)."""
    if keyword.iskeyword(name):
        return f"{name!r} is a Python keyword, and a service's name is a module's: choose another"
    if not NAME.match(name):
        return (
            f"{name!r} is not a service name: use lower-case letters, digits and single "
            f"underscores, starting with a letter ({suggest(name) or 'gps_logger'} would do)"
        )
    if len(name) > MAX_NAME:
        return f"{name!r} is too long for a service name: at most {MAX_NAME} characters"
    return None


def suggest(name: str) -> str | None:
    """A valid name close to `name` (`Bad-Name` -> `bad_name`), or None."""
    words = re.findall(r"[A-Z]?[a-z0-9]+|[A-Z]+(?![a-z])", name)
    candidate = "_".join(w.lower() for w in words)
    ok = NAME.match(candidate) and len(candidate) <= MAX_NAME and not keyword.iskeyword(candidate)
    return candidate if ok else None
