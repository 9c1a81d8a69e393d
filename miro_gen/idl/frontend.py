"""The IDL front end: file -> preprocessed text -> AST -> resolved specification."""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from miro_gen.diagnostics import CompileError, Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.parser import parse
from miro_gen.idl.preprocessor import Preprocessor
from miro_gen.idl.resolver import Resolver
from miro_gen.idl.rosidl import is_interface_file


def compile_idl(
    path: str,
    include_dirs: Sequence[str] = (),
    defines: dict[str, str | None] | None = None,
    diagnostics: Diagnostics | None = None,
    *,
    case_sensitive: bool = False,
    ros2: bool = False,
) -> ast.Specification:
    """Parse and resolve one IDL file (one translation unit, with its includes).

    Problems are collected in `diagnostics`; `CompileError` is raised if any of them is an error.
    `case_sensitive` reads DDS and ROS 2 files as Cyclone's `idlc -f case-sensitive` does:
    identifiers that differ in case are distinct, and only exact keywords are reserved.
    `ros2` reads a `.idl` as ROS 2's rosidl does (`rosidl/unit.py`: each file once, identical
    redeclarations, the types derived from services and actions, RIHS01 hashes); `.msg`,
    `.srv` and `.action` files are always read so.
    """
    diag = diagnostics if diagnostics is not None else Diagnostics()
    resolver = Resolver(diag, case_sensitive)
    try:
        with _recursion_limit(RECURSION_LIMIT):
            if ros2 or is_interface_file(path):
                from miro_gen.idl.rosidl.unit import compile_ros2  # lark and the .msg readers

                return compile_ros2(path, include_dirs, defines, diag)
            return _compile(path, include_dirs, defines, diag, resolver)
    except RecursionError:
        where = resolver.last_pos or SourcePos(path, 1, 1)
        diag.error(where, "declarations or expressions nested too deeply for miro-idl")
        raise CompileError(diag.items) from None


# Pathologically nested input (thousands of levels) recurses in the resolver and the constant
# evaluator; Python 3.11 runs Python-to-Python calls without growing the C stack, so a higher
# limit is safe, and beyond it the user gets a message instead of a traceback.
RECURSION_LIMIT = 20_000


@contextmanager
def _recursion_limit(limit: int) -> Iterator[None]:
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old, limit))
    try:
        yield
    finally:
        sys.setrecursionlimit(old)


def _compile(
    path: str,
    include_dirs: Sequence[str],
    defines: dict[str, str | None] | None,
    diag: Diagnostics,
    resolver: Resolver,
) -> ast.Specification:
    before = diag.error_count
    src = Preprocessor(list(include_dirs), defines, diag).run(path)
    if diag.error_count > before:
        raise CompileError(diag.items)
    definitions = parse(src, diag, resolver.case_sensitive)
    if definitions is None:  # a syntax error: nothing to resolve
        raise CompileError(diag.items)
    declarations = resolver.resolve(definitions)
    if diag.error_count > before:
        raise CompileError(diag.items)
    if not declarations:
        diag.warning(
            SourcePos(path, 1, 1),
            "the file declares nothing (it is empty, all comments, or its declarations are "
            "left out by #if/#ifdef)",
        )
    return ast.Specification(path, definitions, declarations, src.includes)
