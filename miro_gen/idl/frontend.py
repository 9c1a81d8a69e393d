"""The IDL front end: file -> preprocessed text -> AST -> resolved specification."""

from __future__ import annotations

from collections.abc import Sequence

from miro_gen.diagnostics import CompileError, Diagnostics
from miro_gen.idl import ast
from miro_gen.idl.parser import parse
from miro_gen.idl.preprocessor import Preprocessor
from miro_gen.idl.resolver import Resolver


def compile_idl(
    path: str,
    include_dirs: Sequence[str] = (),
    defines: dict[str, str] | None = None,
    diagnostics: Diagnostics | None = None,
) -> ast.Specification:
    """Parse and resolve one IDL file (one translation unit, with its includes).

    Problems are collected in `diagnostics`; `CompileError` is raised if any of them is an error.
    """
    diag = diagnostics if diagnostics is not None else Diagnostics()
    before = diag.error_count
    src = Preprocessor(list(include_dirs), defines, diag).run(path)
    if diag.error_count > before:
        raise CompileError(diag.items)
    definitions = parse(src, diag)
    if diag.error_count > before:
        raise CompileError(diag.items)
    declarations = Resolver(diag).resolve(definitions)
    if diag.error_count > before:
        raise CompileError(diag.items)
    return ast.Specification(path, definitions, declarations, src.includes)
