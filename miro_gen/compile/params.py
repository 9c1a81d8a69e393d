"""Compile-time parameter files (makeParams XML) into an importable package: read with their
includes (params/compiler/loader.py), built into modules, rendered and written at once, or
only compared with what is there (`check`). Nothing is printed."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen.compile import checks
from miro_gen.compile.idl import NESTED_TOO_DEEPLY, cannot_write
from miro_gen.compile.outcome import Outcome
from miro_gen.diagnostics import CompileError, Diagnostics

if TYPE_CHECKING:
    from miro_gen.params.compiler.pymodel import PyParamsModule


def params_package(
    files: Sequence[str],
    outdir: str | Path,
    *,
    include_dirs: Sequence[str] = (),
    name: str | None = None,
    python_classes: Mapping[str, str] | None = None,
    skip_untranslatable: bool = False,
    check: bool = False,
    base: Path | None = None,
    diagnostics: Diagnostics | None = None,
) -> Outcome:
    """Compile parameter `files` into Python modules in `outdir`, or with `check` only list the
    generated files that would change. `name`: the module name of the one file (else its
    stem); `python_classes`: hand-written classes of dummy items (TYPE -> MODULE); `base`: the
    folder generated files name their sources relative to (default: the working folder).
    Problems found before (`diagnostics`: the command line's) are reported with the run's."""
    diag = diagnostics if diagnostics is not None else Diagnostics()
    out = Outcome(Path(outdir))
    checks.unreadable_params(list(files), diag)
    if name is not None and len(files) != 1:
        diag.error(None, "-n NAME names the module of one FILE; give one")
    if out.outdir.exists() and not out.outdir.is_dir():
        diag.error(None, f"the output folder '{outdir}' is a file (-o OUTDIR)")
    if diag.has_errors:
        out.diagnostics = diag.sorted_items()
        return out
    try:
        modules = params_modules(
            files, include_dirs, name, diag, python_classes, skip_untranslatable, base
        )
    except CompileError:  # too many errors
        out.diagnostics = diag.sorted_items()
        return out
    except RecursionError:  # classes deriving from each other thousands deep, ...
        out.diagnostics = diag.sorted_items()
        out.errors.append(NESTED_TOO_DEEPLY)
        return out
    out.diagnostics = diag.sorted_items()
    if diag.has_errors:
        return out
    from miro_gen.codegen.generate import changed_files, write_files
    from miro_gen.params.compiler import generate

    generated = generate.generated_files(modules, out.outdir)
    out.files = len(generated)
    out.changed = changed_files(generated, out.outdir)
    if check:
        return out
    try:
        write_files(generated, out.changed, out.outdir)
    except OSError as e:
        out.errors.append(cannot_write(e, out.outdir))
        return out
    out.written = True
    return out


def params_modules(
    paths: Sequence[str],
    include_dirs: Sequence[str],
    name: str | None,
    diag: Diagnostics,
    python_classes: Mapping[str, str] | None = None,
    skip_untranslatable: bool = False,
    base: Path | None = None,
) -> list[PyParamsModule]:
    """The modules of the parameter files `paths` (errors in `diag`), not rendered."""
    from miro_gen.params.compiler.build import build_modules
    from miro_gen.params.compiler.loader import Loader
    from miro_gen.params.compiler.pymodel import PyParamsModule

    loader = Loader(list(include_dirs), diag, base)
    targets = []
    for path in paths:
        f = loader.load(Path(path))
        if f is not None:
            targets.append(f)
    names = {Path(paths[0]).resolve(): name} if name else {}
    built = build_modules(
        list(loader.files.values()),
        targets,
        names,
        diag,
        dict(python_classes or {}),
        skip_untranslatable=skip_untranslatable,
    )
    return [m for m in built if isinstance(m, PyParamsModule)]
