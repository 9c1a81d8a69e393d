"""`miro-idl`: the OMG IDL compiler's command line."""

from __future__ import annotations

import argparse
import gc
import os
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from miro_gen.cli import idl_checks as checks
from miro_gen.cli.common import VersionAction, internal_error, parse_defines
from miro_gen.diagnostics import CompileError, Diagnostics

DESCRIPTION = """\
Compile OMG IDL files. Each FILE is preprocessed (#include, #define, #if...), parsed and resolved
as CORBA compilers do; every problem is reported as `path:line:col: error: message` and makes the
command exit with status 1 without writing anything.
"""

EPILOG = """\
examples:
  miro-idl --ast-json idl/Example.idl          print the resolved declarations as JSON
  miro-idl -I idl -o generated idl/*.idl       generate Python into generated/
  miro-idl -I idl --check idl/*.idl            fail if generated/ is stale (for CI)
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro-idl",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="IDL files to compile")
    p.add_argument(
        "-I",
        dest="include_dirs",
        action="append",
        default=[],
        metavar="DIR",
        help="add DIR to the #include search path (searched after the including file's folder); "
        "may be repeated",
    )
    p.add_argument(
        "-D",
        dest="defines",
        action="append",
        default=[],
        type=lambda text: ("D", text),
        metavar="NAME[=VALUE]",
        help="define a preprocessor macro (VALUE defaults to 1); may be repeated",
    )
    p.add_argument(
        "-U",
        dest="defines",
        action="append",
        type=lambda text: ("U", text),
        metavar="NAME",
        help="undefine a predefined macro (__MIRO_IDL__, __OMNIIDL__); may be repeated",
    )
    p.add_argument(
        "-o",
        dest="outdir",
        default="generated",
        metavar="OUTDIR",
        help="folder for the generated Python packages (default: generated)",
    )
    p.add_argument(
        "--case-sensitive",
        action="store_true",
        help="identifiers that differ only in case are distinct (DDS and ROS 2 files, as idlc's "
        "-f case-sensitive): `Header header;` is a member named like its type",
    )
    p.add_argument(
        "--ros2",
        action="store_true",
        help="read .idl files as ROS 2's rosidl does (each file once, identical redeclarations, "
        "the types derived from services and actions, RIHS01 type hashes); .msg, .srv and "
        ".action files are always read so (give the folder holding their packages with -I)",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--check",
        action="store_true",
        help="write nothing; exit 1 listing every generated file that would change",
    )
    mode.add_argument(
        "--ast-json",
        action="store_true",
        help="print the resolved AST as JSON on stdout and write nothing",
    )
    p.add_argument("--version", action=VersionAction)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    # A compiler run is short and allocation-heavy: cyclic garbage collection would only rescan
    # the growing AST (about 10% of the run time on large files).
    gc.disable()
    args = build_parser().parse_args(argv)
    from miro_gen.idl.frontend import RECURSION_LIMIT

    sys.setrecursionlimit(max(sys.getrecursionlimit(), RECURSION_LIMIT))  # see frontend.py
    diag = Diagnostics()
    defines = parse_defines(args.defines, diag)
    for f in args.files:
        problem = checks.unreadable(f)
        if problem:
            diag.error(None, f"cannot read '{f}': {problem}")
    if not args.ast_json:
        problem = checks.unusable_outdir(args.outdir, writing=not args.check)
        if problem:
            diag.error(None, f"-o {args.outdir}: {problem}")
    if diag.has_errors:
        diag.print()
        return 1
    try:
        return _run(args, defines, diag)
    except CompileError:
        diag.print()
        return 1
    except KeyboardInterrupt:
        return 130
    except RecursionError:
        diag.print()
        print("miro-idl: error: the input is nested too deeply to process", file=sys.stderr)
        return 1
    except Exception as e:  # a bug in miro-idl, not in the input
        diag.print()
        return internal_error("miro-idl", e)


def _run(args: argparse.Namespace, defines: dict[str, str | None], diag: Diagnostics) -> int:
    from miro_gen.idl.frontend import compile_idl

    specs = []
    failed = False
    for path in args.files:
        try:
            specs.append(
                compile_idl(
                    path,
                    args.include_dirs,
                    defines,
                    diag,
                    case_sensitive=args.case_sensitive,
                    ros2=args.ros2,
                )
            )
        except CompileError:
            failed = True  # keep going: report the problems of every file
    diag.print()
    if failed:
        return 1
    if args.ast_json:
        from miro_gen.idl.ast_json import dumps, specifications_json

        sys.stdout.write(dumps(specifications_json(list(args.files), specs)))
        sys.stdout.flush()
        return 0
    return _generate(args, specs, defines)


def _generate(args: argparse.Namespace, specs: list[Any], defines: dict[str, str | None]) -> int:
    from pathlib import Path

    from miro_gen.codegen import generate
    from miro_gen.idl.frontend import compile_idl

    outdir = Path(args.outdir)
    refusals = Diagnostics()  # the compile diagnostics are printed already
    checks.clashing_declarations(specs, refusals)
    if refusals.has_errors:
        refusals.print()
        return 1
    modules = generate.build_modules(zip(specs, args.files, strict=True), refusals)
    if refusals.has_errors:
        refusals.print()
        return 1
    too_long = checks.too_long_paths([m.path for m in modules], outdir)
    for message in too_long:
        print(f"miro-idl: error: {message}", file=sys.stderr)
    if too_long:
        return 1
    planned = generate.planned_files(modules, outdir)
    missing = [
        m
        for m in generate.missing_imports(modules, {rel for rel, _ in planned}, outdir)
        if not checks.installed(m)
    ]
    if missing:

        def compile_dependency(path: str, into: Diagnostics) -> Any:
            return compile_idl(
                path,
                args.include_dirs,
                defines,
                into,
                case_sensitive=args.case_sensitive,
                ros2=args.ros2,
            )

        checks.refused_dependencies(specs, modules, missing, compile_dependency, refusals)
        if refusals.has_errors:
            refusals.print()
            return 1
    for module in missing:
        print(
            f"miro-idl: warning: the generated code imports {module}, which is not generated: "
            f"compile the IDL file it comes from too",
            file=sys.stderr,
        )
    for package in generate.shadowed_modules(modules):
        print(
            f"miro-idl: warning: IDL module {package} is the Python package {package}, which hides "
            f"the standard library's {package} module from programs with {outdir} on sys.path",
            file=sys.stderr,
        )
    try:  # rendered only now, and written only if every file can be
        changed = generate.write_planned(planned, outdir, check=args.check)
    except OSError as e:
        where = checks.shorten(str(e.filename or outdir))
        print(f"miro-idl: error: cannot write '{where}': {e.strerror or e}", file=sys.stderr)
        return 1
    if args.check:
        for rel in changed:
            print(f"miro-idl: {outdir / rel} is out of date", file=sys.stderr)
        return 1 if changed else 0
    for rel in changed:
        print(f"wrote {outdir / rel}")
    if not changed:
        print(f"miro-idl: {len(planned)} files in {outdir} are up to date")
    return 0


def run() -> NoReturn:
    """The `miro-idl` command: `main()`, then an exit that skips freeing the AST object by
    object (a tenth of the run time on large files; there is nothing else to clean up, and
    the output is flushed first)."""
    code = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError:  # a closed pipe (`miro-idl --ast-json ... | head`)
        code = code or 1
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    run()
