"""`miro-idl`: the OMG IDL compiler's command line."""

from __future__ import annotations

import argparse
import gc
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from miro_gen.cli.common import VersionAction, internal_error, parse_defines, show
from miro_gen.compile.idl import idl_package
from miro_gen.diagnostics import Diagnostics

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


def command(argv: Sequence[str]) -> int:
    """`miro idl`: `main` in a process that ends with it (see `run`)."""
    gc.disable()
    return main(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    diag = Diagnostics()
    defines = parse_defines(args.defines, diag)
    try:
        done = idl_package(
            args.files,
            args.outdir,
            include_dirs=args.include_dirs,
            defines=defines,
            case_sensitive=args.case_sensitive,
            ros2=args.ros2,
            check=args.check,
            generate=not args.ast_json,
            diagnostics=diag,
        )
    except KeyboardInterrupt:
        return 130
    except Exception as e:  # a bug in miro-idl, not in the input
        diag.print()
        return internal_error("miro-idl", e)
    if args.ast_json and done.ok:
        from miro_gen.idl.ast_json import dumps, specifications_json

        show(done, "miro-idl", check=False)
        sys.stdout.write(dumps(specifications_json(list(args.files), done.specs)))
        sys.stdout.flush()
        return 0
    return show(done, "miro-idl", args.check)


def run() -> NoReturn:
    """The `miro-idl` command: `main()` without cyclic garbage collection (a compiler run is
    short and allocation-heavy: the collector would only rescan the growing AST, about 10% of
    the run time on large files), then an exit that skips freeing the AST object by object (a
    tenth again; there is nothing else to clean up, and the output is flushed first)."""
    gc.disable()  # this process ends with the run
    code = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError:  # a closed pipe (`miro-idl --ast-json ... | head`)
        code = code or 1
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    run()
