"""Generation of Python from resolved IDL: the files `miro-idl` writes, and how it writes them.

The pipeline: each IDL file's resolved specification is lowered into module contexts
(`lower.py`), the package `__init__`s are built from those (`packages.py`), and everything is
rendered in memory (`render.py`); only then are files written, each through a temporary file
renamed into place, so that an error leaves the output folder as it was.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from pathlib import Path

from miro_gen.codegen import python_limits
from miro_gen.codegen.contexts import ModuleContext
from miro_gen.codegen.lower import lower_file
from miro_gen.codegen.packages import GENERATED_MARK, package_contexts
from miro_gen.codegen.render import render_module, render_package_init
from miro_gen.codegen.shapes import Unsupported
from miro_gen.diagnostics import Diagnostics
from miro_gen.idl import ast

__all__ = [
    "GENERATED_MARK",
    "build_modules",
    "changed_files",
    "display_source",
    "generated_files",
    "missing_imports",
    "shadowed_modules",
    "write_files",
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


def generated_files(modules: list[ModuleContext], outdir: Path) -> dict[str, str]:
    """Relative path -> content of every file to write, package `__init__`s included."""
    files: dict[str, str] = {}
    for m in modules:
        if m.path not in files:  # the same IDL file compiled twice: the first one
            files[m.path] = render_module(m)
    for package in package_contexts(modules, outdir):
        files[package.path] = render_package_init(package)
        if "." not in package.package:  # PEP 561: mypy checks against it where installed
            files[package.package + "/py.typed"] = ""
    return files


def missing_imports(modules: list[ModuleContext], files: dict[str, str], outdir: Path) -> list[str]:
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


def changed_files(files: dict[str, str], outdir: Path) -> list[str]:
    """The relative paths whose content on disk differs (or that do not exist)."""
    out = []
    for rel, content in sorted(files.items()):
        path = outdir / rel
        try:
            if path.read_text(encoding="utf-8") == content:
                continue
        except (OSError, UnicodeDecodeError):
            pass
        out.append(rel)
    return out


def write_files(files: dict[str, str], rels: list[str], outdir: Path) -> None:
    """Write `rels` of `files` under `outdir`: all to temporary files first, then renamed."""
    staged: list[tuple[Path, Path]] = []
    try:
        for rel in rels:
            path = outdir / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            tmp.write_text(files[rel], encoding="utf-8")
            staged.append((tmp, path))
        for tmp, path in staged:
            os.replace(tmp, path)
    finally:
        for tmp, _ in staged:
            if tmp.exists():
                tmp.unlink()
