"""Helpers shared by the command-line front ends."""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from miro_gen.diagnostics import Diagnostics

if TYPE_CHECKING:
    from miro_gen.compile.outcome import Outcome

_MACRO_NAME = re.compile(r"[A-Za-z_]\w*$")


def parse_defines(items: list[tuple[str, str]], diag: Diagnostics) -> dict[str, str | None]:
    """`-D NAME`, `-D NAME=VALUE` and `-U NAME` options, as ("D" or "U", text) in command-line
    order, as a macro table: None undefines a predefined macro."""
    out: dict[str, str | None] = {}
    for option, item in items:
        name, sep, value = item.partition("=") if option == "D" else (item, "", "")
        if not _MACRO_NAME.match(name):
            diag.error(None, f"invalid macro name in -{option} {item!r}")
            continue
        out[name] = None if option == "U" else value if sep else "1"
    return out


def show(done: Outcome, prog: str, check: bool) -> int:
    """Print what a compile did as the compilers' command lines do; their exit status."""
    for d in done.diagnostics:
        print(d, file=sys.stderr)
    for text in done.warnings:
        print(f"{prog}: warning: {text}", file=sys.stderr)
    for text in done.errors:
        print(f"{prog}: error: {text}", file=sys.stderr)
    if not done.ok:
        return 1
    if check:
        for path in done.paths():
            print(f"{prog}: {path} is out of date", file=sys.stderr)
        return 1 if done.changed else 0
    for path in done.paths():
        print(f"wrote {path}")
    if done.written and not done.changed:
        print(f"{prog}: {done.files} files in {done.outdir} are up to date")
    return 0


def internal_error(prog: str, exc: BaseException) -> int:
    """Report a bug in the tool itself: one line, the traceback only with MIRO_DEBUG=1."""
    print(
        f"{prog}: internal error: {type(exc).__name__}: {exc}\n"
        f"{prog}: this is a bug in miro-gen; please report it with the input that caused it "
        "(set MIRO_DEBUG=1 for a traceback)",
        file=sys.stderr,
    )
    if os.environ.get("MIRO_DEBUG"):
        import traceback  # here only: it costs every command start-up time

        traceback.print_exc()
    return 3


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("miro-gen")
    except PackageNotFoundError:  # running from a source checkout
        return "0+unknown"


class VersionAction(argparse.Action):
    """`--version`, looking the version up only when asked (importlib.metadata is slow to load)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kw: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, help="show the version and exit", **kw)

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kw: Any) -> None:
        print(f"{parser.prog} {package_version()}")
        parser.exit()


def piped(command: Any, argv: Sequence[str]) -> int:
    """Run `command(argv)`; a reader that went away (`| head`) ends it quietly."""
    try:
        return int(command(argv))
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so that the exit's flush does not fail again
        return 0
