"""What a compile into a package did, for its caller to show as it needs: a command prints it,
`miro build` sums it up, `miro new` stops on it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen.diagnostics import Diagnostic

if TYPE_CHECKING:
    from miro_gen.idl.ast import Specification


class Outcome:
    """Diagnostics at positions in the inputs (`path:line:col: error: ...`, in the order to
    show them), problems of the run itself (`errors`: output paths too long, a file that
    cannot be written) and its warnings, the generated files, and which of them changed.

    A plain class, not a dataclass: `dataclasses` imports `inspect`, a tenth of what
    `miro-idl` imports before it reads a file."""

    __slots__ = (
        "changed",
        "diagnostics",
        "errors",
        "files",
        "outdir",
        "specs",
        "warnings",
        "written",
    )

    def __init__(self, outdir: Path) -> None:
        self.outdir = outdir
        self.diagnostics: list[Diagnostic] = []
        self.errors: list[str] = []
        self.warnings: list[str] = []
        self.files = 0  # files generated (in memory)
        self.changed: list[str] = []  # relative to outdir: written, or stale
        self.written = False  # `changed` were written (not a check)
        self.specs: list[Specification] = []  # IDL: the resolved specifications

    @property
    def ok(self) -> bool:
        """Compiled without an error (a check may still have found stale files)."""
        return not self.errors and not any(d.severity == "error" for d in self.diagnostics)

    def paths(self) -> list[Path]:
        """The changed files, under `outdir`."""
        return [self.outdir / rel for rel in self.changed]
