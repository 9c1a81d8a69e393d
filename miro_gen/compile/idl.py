"""IDL files into an importable package: preprocessed, parsed and resolved (idl/), refused
where the generated code could not work (checks.py), generated (codegen/) and written at once,
or only compared with what is there (`check`).

Nothing is printed and nothing of the process is changed (its working folder, its garbage
collector); the recursion limit is raised only while compiling, as deeply nested input needs.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from miro_gen.compile import checks
from miro_gen.compile.outcome import Outcome
from miro_gen.diagnostics import CompileError, Diagnostics
from miro_gen.idl import ast
from miro_gen.idl.frontend import RECURSION_LIMIT, compile_idl

NESTED_TOO_DEEPLY = "the input is nested too deeply to process"


def idl_package(
    files: Sequence[str],
    outdir: str | Path,
    *,
    include_dirs: Sequence[str] = (),
    defines: Mapping[str, str | None] | None = None,
    case_sensitive: bool = False,
    ros2: bool = False,
    check: bool = False,
    generate: bool = True,
    base: Path | None = None,
    diagnostics: Diagnostics | None = None,
) -> Outcome:
    """Compile IDL `files` into Python packages in `outdir` (made if missing), or with `check`
    only list the generated files that would change; `generate=False` stops at the resolved
    specifications (`Outcome.specs`). `base` is the folder generated files name their sources
    relative to (default: the working folder; `miro build` gives the project's); `ros2` reads
    `.idl` files as rosidl does (`idl/frontend.py`). Problems found
    before (`diagnostics`: the command line's) are reported with the run's."""
    diag = diagnostics if diagnostics is not None else Diagnostics()
    out = Outcome(Path(outdir))
    for f in files:
        problem = checks.unreadable(f)
        if problem:
            diag.error(None, f"cannot read '{f}': {problem}")
    if generate:
        problem = checks.unusable_outdir(str(outdir), writing=not check)
        if problem:
            diag.error(None, f"-o {outdir}: {problem}")
    if diag.has_errors:
        out.diagnostics = diag.sorted_items()
        return out
    front_end = _FrontEnd(include_dirs, dict(defines or {}), case_sensitive, ros2)
    try:
        with _deep_recursion():
            specs = front_end.read(files, diag)
            out.diagnostics = diag.sorted_items()
            if specs is not None and generate:
                out.specs = specs
                _generate(out, files, specs, front_end, check, base)
            elif specs is not None:
                out.specs = specs
    except CompileError:  # too many errors
        out.diagnostics = diag.sorted_items()
    except RecursionError:
        out.diagnostics = diag.sorted_items()
        out.errors.append(NESTED_TOO_DEEPLY)
    return out


class _FrontEnd:
    """The front end with one run's search path, macros, case rule and reading of `.idl`
    files (OMG's or rosidl's)."""

    def __init__(
        self,
        include_dirs: Sequence[str],
        defines: dict[str, str | None],
        case_sensitive: bool,
        ros2: bool,
    ) -> None:
        self.include_dirs = list(include_dirs)
        self.defines = defines
        self.case_sensitive = case_sensitive
        self.ros2 = ros2

    def spec(self, path: str, diag: Diagnostics) -> ast.Specification:
        return compile_idl(
            path,
            self.include_dirs,
            self.defines,
            diag,
            case_sensitive=self.case_sensitive,
            ros2=self.ros2,
        )

    def read(self, files: Sequence[str], diag: Diagnostics) -> list[ast.Specification] | None:
        """Every file's specification; None when any does not compile (each one is tried, so
        that the problems of all are reported)."""
        specs = []
        failed = False
        for path in files:
            try:
                specs.append(self.spec(path, diag))
            except CompileError:
                failed = True
        return None if failed else specs


def _generate(
    out: Outcome,
    paths: Sequence[str],
    specs: list[ast.Specification],
    front_end: _FrontEnd,
    check: bool,
    base: Path | None,
) -> None:
    from miro_gen.codegen import generate

    refusals = Diagnostics()
    checks.clashing_declarations(specs, refusals)
    if refusals.has_errors:
        out.diagnostics += refusals.sorted_items()
        return
    modules = generate.build_modules(zip(specs, paths, strict=True), refusals, base)
    if refusals.has_errors:
        out.diagnostics += refusals.sorted_items()
        return
    out.errors += checks.too_long_paths([m.path for m in modules], out.outdir)
    if out.errors:
        return
    planned = generate.planned_files(modules, out.outdir)
    missing = [
        m
        for m in generate.missing_imports(modules, {rel for rel, _ in planned}, out.outdir)
        if not checks.installed(m)
    ]
    if missing:
        checks.refused_dependencies(specs, modules, missing, front_end.spec, refusals)
        if refusals.has_errors:
            out.diagnostics += refusals.sorted_items()
            return
    out.warnings += [
        f"the generated code imports {module}, which is not generated: compile the IDL file "
        "it comes from too"
        for module in missing
    ]
    out.warnings += [
        f"IDL module {package} is the Python package {package}, which hides the standard "
        f"library's {package} module from programs with {out.outdir} on sys.path"
        for package in generate.shadowed_modules(modules)
    ]
    out.files = len(planned)
    try:  # rendered only now, and written only if every file can be
        out.changed = generate.write_planned(planned, out.outdir, check=check)
    except OSError as e:
        out.errors.append(cannot_write(e, out.outdir))
        return
    out.written = not check


def cannot_write(e: OSError, outdir: Path) -> str:
    """Why a generated file could not be written, in one line."""
    where = checks.shorten(str(e.filename or outdir))
    why = (
        "a file is in the way of a folder"
        if isinstance(e, FileExistsError | NotADirectoryError)
        else e.strerror or str(e)
    )
    return f"cannot write '{where}': {why}"


@contextmanager
def _deep_recursion() -> Iterator[None]:
    """Python's recursion limit raised for this compile only (see idl/frontend.py)."""
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old, RECURSION_LIMIT))
    try:
        yield
    finally:
        sys.setrecursionlimit(old)
