"""Compiler diagnostics: positions, errors and warnings in `path:line:col: error: message` form.

Every tool of the project reports problems in its input through a `Diagnostics` collector, so that
several problems are reported per run and the command-line front ends can print them uniformly and
exit 1 without a traceback.
"""

from __future__ import annotations

import sys
from typing import NamedTuple, TextIO


class SourcePos(NamedTuple):
    """A position in an original source file (1-based line and column; column 0 when unknown).

    A named tuple: parsers create one per declaration, and tuples are cheap to build.
    """

    path: str
    line: int
    col: int

    def __str__(self) -> str:
        # col 0: only the line is known (lxml reports no columns for elements)
        if self.col <= 0:
            return f"{self.path}:{self.line}"
        return f"{self.path}:{self.line}:{self.col}"


class Diagnostic(NamedTuple):
    severity: str  # "error", "warning" or "note"
    pos: SourcePos | None
    message: str

    def __str__(self) -> str:
        where = f"{self.pos}: " if self.pos is not None else ""
        return f"{where}{self.severity}: {self.message}"


class CompileError(Exception):
    """Raised when input is invalid; carries every diagnostic collected up to that point."""

    def __init__(self, diagnostics: list[Diagnostic]) -> None:
        self.diagnostics = diagnostics
        errors = [d for d in diagnostics if d.severity == "error"]
        super().__init__(str(errors[0]) if errors else "compilation failed")


class Diagnostics:
    """Collects diagnostics; `check()` raises `CompileError` once any error was reported."""

    def __init__(self, max_errors: int = 100) -> None:
        self.items: list[Diagnostic] = []
        self.max_errors = max_errors

    def error(self, pos: SourcePos | None, message: str) -> None:
        self.items.append(Diagnostic("error", pos, message))
        self.check_limit()

    def check_limit(self) -> None:
        """Stop (CompileError) once the maximum number of errors is reached."""
        if self.error_count >= self.max_errors:
            self.items.append(Diagnostic("note", None, "too many errors; stopping"))
            raise CompileError(self.items)

    def warning(self, pos: SourcePos | None, message: str) -> None:
        self.items.append(Diagnostic("warning", pos, message))

    def note(self, pos: SourcePos | None, message: str) -> None:
        self.items.append(Diagnostic("note", pos, message))

    @property
    def error_count(self) -> int:
        return sum(1 for d in self.items if d.severity == "error")

    @property
    def has_errors(self) -> bool:
        return any(d.severity == "error" for d in self.items)

    def check(self) -> None:
        if self.has_errors:
            raise CompileError(self.items)

    def sorted_items(self) -> list[Diagnostic]:
        """Diagnostics in source order (files in order of first mention); each note stays after
        the diagnostic it belongs to. Different phases report in their own order otherwise."""
        groups: list[list[Diagnostic]] = []
        for d in self.items:
            if d.severity == "note" and groups:
                groups[-1].append(d)
            else:
                groups.append([d])
        rank: dict[str, int] = {}
        for d in self.items:
            if d.pos is not None:
                rank.setdefault(d.pos.path, len(rank))

        def key(group: list[Diagnostic]) -> tuple[int, int, int]:
            pos = group[0].pos
            return (-1, 0, 0) if pos is None else (rank[pos.path], pos.line, pos.col)

        return [d for group in sorted(groups, key=key) for d in group]

    def print(self, stream: TextIO | None = None) -> None:
        out = stream if stream is not None else sys.stderr
        for d in self.sorted_items():
            print(d, file=out)
