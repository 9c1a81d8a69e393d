"""Generation of Python from resolved IDL: the files `miro-idl` writes, and how it writes them.

The pipeline: each IDL file's resolved specification is lowered into module contexts
(`lower.py`), the package `__init__`s are built from those (`packages.py`): together the
planned files (`planned_files`), each rendered by `render` (`render.py`) and written through
`output.py`, which leaves the output folder as it was when anything fails.
"""

from __future__ import annotations

import sys
from collections.abc import Collection, Iterable
from pathlib import Path

from miro_gen.codegen import python_limits
from miro_gen.codegen.contexts import InterfaceContext, ModuleContext, PackageContext
from miro_gen.codegen.lower import lower_file
from miro_gen.codegen.output import changed_files, update, write_files
from miro_gen.codegen.packages import GENERATED_MARK, package_contexts
from miro_gen.codegen.render import preload, render_module, render_package_init
from miro_gen.codegen.shapes import Unsupported, member_shape
from miro_gen.diagnostics import Diagnostics
from miro_gen.idl import ast

__all__ = [
    "GENERATED_MARK",
    "build_modules",
    "changed_files",
    "display_source",
    "generated_files",
    "missing_imports",
    "planned_files",
    "render",
    "shadowed_modules",
    "update",
    "write_files",
    "write_planned",
]


def display_source(path: str, base: Path | None = None) -> str:
    """How generated files name their IDL source: relative to `base` (default: the working
    folder) when inside it, otherwise the file name (no absolute paths in output)."""
    p = Path(path)
    try:
        rel = p.resolve().relative_to((base or Path.cwd()).resolve())
        return rel.as_posix()
    except ValueError:
        return p.name


def build_modules(
    specs: Iterable[tuple[ast.Specification, str]], diag: Diagnostics, base: Path | None = None
) -> list[ModuleContext]:
    """The Python modules of each (specification, main IDL file); refusals become errors.
    Sources are named relative to `base` (`display_source`)."""
    try:
        return _build_modules(specs, diag, base)
    finally:
        member_shape.cache_clear()  # the shapes of this compilation's members


def _build_modules(
    specs: Iterable[tuple[ast.Specification, str]], diag: Diagnostics, base: Path | None
) -> list[ModuleContext]:
    modules: list[ModuleContext] = []
    declarations: dict[str, ast.Decl] = {}
    for spec, path in specs:
        try:
            mine = [d for d in spec.declarations if d.pos.path == path]
            python_limits.check_inheritance(mine)
            python_limits.check_nested_names(mine, spec.declarations)
            modules += lower_file(spec, path, display_source(path, base))
        except Unsupported as e:
            diag.error(e.pos, e.message)
        for d in spec.declarations:
            if not isinstance(d, ast.Forward):
                declarations.setdefault(d.scoped_name, d)
    for pos, message in python_limits.base_class_cycles(modules, declarations):
        diag.error(pos, message)
    return modules


Planned = tuple[str, ModuleContext | PackageContext | None]  # (relative path, its context)


def planned_files(modules: list[ModuleContext], outdir: Path) -> list[Planned]:
    """Every file to write, package `__init__`s included, by relative path (sorted), with
    the context it is rendered from (None: an empty file)."""
    files: dict[str, ModuleContext | PackageContext | None] = {}
    for m in modules:
        files.setdefault(m.path, m)  # the same IDL file compiled twice: the first one
    for package in package_contexts(modules, outdir):
        files[package.path] = package
        if "." not in package.package:  # PEP 561: mypy checks against it where installed
            files[package.package + "/py.typed"] = None
    return sorted(files.items())


def render(context: ModuleContext | PackageContext | None) -> str:
    """The content of a planned file."""
    if context is None:
        return ""
    if isinstance(context, ModuleContext):
        return render_module(context)
    return render_package_init(context)


# What making a file costs (on a busy disk), in declarations rendered: for sharing out the work.
FILE_WEIGHT = 10


def write_planned(planned: list[Planned], outdir: Path, *, check: bool) -> list[str]:
    """Render the planned files and bring `outdir` up to date with them, or with `check` only
    compare (`output.update`); the paths that differ. The templates are loaded first, once,
    rather than by each process that renders."""
    preload()
    return update(planned, render, outdir, check=check, weight=_weight)


def _weight(context: ModuleContext | PackageContext | None) -> int:
    """About what a planned file costs: making it (as much as rendering ten declarations, on
    a busy disk), and rendering its declarations, most for the operations of stubs and
    skeletons."""
    if isinstance(context, ModuleContext):
        interfaces = [i for i in context.items if isinstance(i, InterfaceContext)]
        return FILE_WEIGHT + len(context.items) + 3 * sum(len(i.operations) for i in interfaces)
    return FILE_WEIGHT + (0 if context is None else 1)


def generated_files(modules: list[ModuleContext], outdir: Path) -> dict[str, str]:
    """Relative path -> content of every file to write, package `__init__`s included."""
    return {rel: render(context) for rel, context in planned_files(modules, outdir)}


def missing_imports(
    modules: list[ModuleContext], files: Collection[str], outdir: Path
) -> list[str]:
    """Generated modules imported by these ones that neither this run nor an earlier one wrote
    (an included IDL file that was not compiled)."""
    out = []
    for m in modules:
        for imported in sorted(m.imports):
            rel = imported.replace(".", "/") + ".py"
            if rel not in files and not (outdir / rel).is_file() and imported not in out:
                out.append(imported)
    return out


def shadowed_modules(modules: list[ModuleContext]) -> list[str]:
    """The top-level packages of these modules that are named like a standard-library module
    (IDL `module queue`): wherever the output folder comes first on sys.path, every program
    imports the generated package in its place (miro_gen's `import queue` too)."""
    return sorted({m.package.split(".")[0] for m in modules} & sys.stdlib_module_names)
