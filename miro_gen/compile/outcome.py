"""What a compile into a package did, for its caller to show as it needs: a command prints it,
`miro build` sums it up, `miro new` stops on it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen.diagnostics import Diagnostic

if TYPE_CHECKING:
    from miro_gen.idl.ast import Specification


@dataclass
class Outcome:
    """Diagnostics at positions in the inputs (`path:line:col: error: ...`, in the order to
    show them), problems of the run itself (`errors`: output paths too long, a file that
    cannot be written) and its warnings, the generated files, and which of them changed."""

    outdir: Path
    diagnostics: list[Diagnostic] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    files: int = 0  # files generated (in memory)
    changed: list[str] = field(default_factory=list)  # relative to outdir: written, or stale
    written: bool = False  # `changed` were written (not a check)
    specs: list[Specification] = field(default_factory=list)  # IDL: the resolved specifications

    @property
    def ok(self) -> bool:
        """Compiled without an error (a check may still have found stale files)."""
        return not self.errors and not any(d.severity == "error" for d in self.diagnostics)

    def paths(self) -> list[Path]:
        """The changed files, under `outdir`."""
        return [self.outdir / rel for rel in self.changed]
