"""`miro-params`: the makeParams compiler's command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from miro_gen.cli.common import VersionAction, internal_error, show
from miro_gen.compile.params import params_package
from miro_gen.diagnostics import CompileError, Diagnostics

DESCRIPTION = """\
Compile makeParams parameter files (config_global, config_group, config_item, config_parameter)
into Python: one module per FILE with a pydantic class per config_item, and the run-time XML
reader, writer and printer of each. Every problem is reported as `path:line: error: message`
and makes the command exit with status 1 without writing anything.

Types: bool, char, short/int/long (signed, unsigned), float, double, string, std::string,
angle (degrees in XML, radians in memory), ACE_Time_Value ("sec, usec"), ACE_INET_Addr
("host:port"), ACE_TTY_IO::Serial_Params, ACE_Sched_Params, Enumeration and EnumerationMultiple
(with values="A B"), vector<T>, set<T>, and parameter classes (XParameters) and IDL structs
(dummy items) of this file or an included one.

default= is read as makeParams pasted it into C++: an expression (150*1024*1024, M_PI/2,
(double)1/3, 0x10, INFINITY), constructor arguments for ACE_Time_Value ("0, 100000") and
ACE_Sched_Params ("ACE_SCHED_FIFO, 50"), a size for vectors. final="false" marks an abstract
class; a dummy item is written by hand (see docs/PARAMS.md and --python-class).
"""

EPILOG = """\
examples:
  miro-params -I idl -o generated params/Parameters.xml  generate generated/Test/Parameters.py
  miro-params -I idl --check params/*.xml               fail if generated/ is stale (for CI)
  miro-params --xsd params/Parameters.xml > p.xsd       a schema of run-time documents
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro-params",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="compile-time parameter files")
    p.add_argument(
        "-I",
        dest="include_dirs",
        action="append",
        default=[],
        metavar="DIR",
        help="add DIR to the search path of included files (after the including file's folder; "
        "the project's params/ is searched last); may be repeated",
    )
    p.add_argument(
        "-o",
        dest="outdir",
        default="generated",
        metavar="OUTDIR",
        help="folder for the generated Python packages (default: generated)",
    )
    p.add_argument(
        "-n",
        dest="name",
        metavar="NAME",
        help="the generated module's name (default: the file's stem); one FILE only",
    )
    p.add_argument(
        "--python-class",
        dest="python_classes",
        action="append",
        default=[],
        metavar="TYPE=MODULE",
        help="the hand-written Python class of the dummy item TYPE (Miro::BAP::Behaviour) is "
        "in MODULE (MODULE:CLASS when it is not TYPE's name with Parameters); may be repeated; "
        'as <config_global name="python_class" type=TYPE value=MODULE/>',
    )
    p.add_argument(
        "--skip-untranslatable",
        action="store_true",
        help="a <constructor> block in C++ beyond what miro-params translates (docs/PARAMS.md) "
        "is left out with a warning, its class keeping the declared defaults, instead of "
        "being an error",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--check",
        action="store_true",
        help="write nothing; exit 1 listing every generated file that would change",
    )
    mode.add_argument(
        "--xsd",
        action="store_true",
        help="print an XML Schema of the run-time documents for these classes (for XML "
        "editors) and write nothing",
    )
    p.add_argument("--version", action=VersionAction)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    diag = Diagnostics()
    python_classes: dict[str, str] = {}
    for given in args.python_classes:
        cxx, eq, module = given.partition("=")
        if not eq or not cxx.strip() or not module.strip():
            diag.error(None, f"--python-class {given!r}: give TYPE=MODULE")
        python_classes[cxx.strip().lstrip(":")] = module.strip()
    args.python_classes = python_classes
    try:
        if args.xsd:
            return _xsd(args, diag)
        done = params_package(
            args.files,
            args.outdir,
            include_dirs=args.include_dirs,
            name=args.name,
            python_classes=python_classes,
            skip_untranslatable=args.skip_untranslatable,
            check=args.check,
            diagnostics=diag,
        )
    except KeyboardInterrupt:
        return 130
    except CompileError:
        diag.print()
        return 1
    except Exception as e:  # a bug in miro-params, not in the input
        diag.print()
        return internal_error("miro-params", e)
    return show(done, "miro-params", args.check)


def _xsd(args: argparse.Namespace, diag: Diagnostics) -> int:
    from miro_gen.compile.checks import unreadable_params
    from miro_gen.params.compiler import dynamic
    from miro_gen.params.compiler.xsd import render_xsd

    unreadable_params(args.files, diag)
    if diag.has_errors:
        diag.print()
        return 1
    classes = dynamic.load(args.files, args.include_dirs, diag, args.python_classes)
    diag.print()
    sys.stdout.write(render_xsd(c.cls for c in classes if c.target))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
