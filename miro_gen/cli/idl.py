"""`miro-idl`: the OMG IDL compiler's command line."""

from __future__ import annotations

import argparse
import gc
import os
import sys
from collections.abc import Sequence
from typing import Any

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
        if not os.path.isfile(f):
            diag.error(None, f"cannot read '{f}': no such file")
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
            specs.append(compile_idl(path, args.include_dirs, defines, diag))
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
    return _generate(args, specs, diag)


def _generate(args: argparse.Namespace, specs: list[Any], diag: Diagnostics) -> int:
    from pathlib import Path

    from miro_gen.codegen import generate

    outdir = Path(args.outdir)
    modules = generate.build_modules(zip(specs, args.files, strict=True), diag)
    if diag.has_errors:
        diag.print()
        return 1
    files = generate.generated_files(modules, outdir)
    for module in generate.missing_imports(modules, files, outdir):
        print(
            f"miro-idl: warning: the generated code imports {module}, which is not generated: "
            f"compile the IDL file it comes from too",
            file=sys.stderr,
        )
    changed = generate.changed_files(files, outdir)
    if args.check:
        for rel in changed:
            print(f"miro-idl: {outdir / rel} is out of date", file=sys.stderr)
        return 1 if changed else 0
    generate.write_files(files, changed, outdir)
    for rel in changed:
        print(f"wrote {outdir / rel}")
    if not changed:
        print(f"miro-idl: {len(files)} files in {outdir} are up to date")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
