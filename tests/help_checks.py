"""Checking `--help` of `miro`, each verb and sub-verb, and the compilers, from the list `miro
--help` prints (shared by tests/cli/test_cli_help.py and tests/project/test_wheel.py, which runs
it against an installed wheel)."""

from __future__ import annotations

import re
from collections.abc import Callable


def verbs(help_text: str) -> list[str]:
    """The sub-commands a help text lists (argparse's lines `    name    what it does`)."""
    return re.findall(r"^ {2,}([a-z][a-z0-9_-]*) {2,}\S", help_text, re.M)


def check_every_help(run: Callable[[str], str]) -> list[str]:
    """`run(command)` (which checks the status and that no traceback shows, and returns the
    standard output) for `--help` of `miro`, each verb and their sub-commands, and of the
    compilers; the commands run."""
    top = run("miro --help")
    listed = verbs(top)
    assert {"demo", "new", "run", "pub", "echo", "bridge"} <= set(listed), top
    done = ["miro --help"]
    for verb in listed:
        text = run(f"miro {verb} --help")
        assert text.strip(), f"miro {verb} --help printed nothing"
        done.append(f"miro {verb} --help")
        if re.search(r"\b(COMMAND|ACTION|KIND)\b", text.splitlines()[0]):
            for sub in verbs(text):
                assert run(f"miro {verb} {sub} --help").strip(), f"miro {verb} {sub} --help"
                done.append(f"miro {verb} {sub} --help")
    for tool in ("miro-idl", "miro-params"):
        assert "usage:" in run(f"{tool} --help")
    return done
