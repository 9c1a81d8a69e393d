"""`miro-params`: the makeParams compiler's command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from miro_gen.cli.common import VersionAction, internal_error
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
    for f in args.files:
        path = Path(f)
        if path.is_dir():
            diag.error(None, f"'{f}' is a folder, not a compile-time file (give its .xml files)")
        elif not path.exists():
            diag.error(None, f"cannot read '{f}': no such file")
    if args.name is not None and len(args.files) != 1:
        diag.error(None, "-n NAME names the module of one FILE; give one")
    outdir = Path(args.outdir)
    if not args.xsd and outdir.exists() and not outdir.is_dir():
        diag.error(None, f"the output folder '{args.outdir}' is a file (-o OUTDIR)")
    python_classes: dict[str, str] = {}
    for given in args.python_classes:
        cxx, eq, module = given.partition("=")
        if not eq or not cxx.strip() or not module.strip():
            diag.error(None, f"--python-class {given!r}: give TYPE=MODULE")
        python_classes[cxx.strip().lstrip(":")] = module.strip()
    args.python_classes = python_classes
    if diag.has_errors:
        diag.print()
        return 1
    try:
        return _run(args, diag)
    except CompileError:
        diag.print()
        return 1
    except KeyboardInterrupt:
        return 130
    except RecursionError:  # classes deriving from each other thousands deep, ...
        diag.print()
        print("miro-params: error: the input is nested too deeply to compile", file=sys.stderr)
        return 1
    except Exception as e:  # a bug in miro-params, not in the input
        diag.print()
        return internal_error("miro-params", e)


def compile_files(
    paths: list[str],
    include_dirs: list[str],
    name: str | None,
    diag: Diagnostics,
    python_classes: dict[str, str] | None = None,
    skip_untranslatable: bool = False,
) -> list[object]:
    """The template contexts of `paths` (errors in `diag`)."""
    from miro_gen.params.compiler.build import build_modules
    from miro_gen.params.compiler.loader import Loader

    loader = Loader(include_dirs, diag)
    targets = []
    for path in paths:
        f = loader.load(Path(path))
        if f is not None:
            targets.append(f)
    names = {Path(paths[0]).resolve(): name} if name else {}
    files = list(loader.files.values())
    return list(
        build_modules(
            files, targets, names, diag, python_classes, skip_untranslatable=skip_untranslatable
        )
    )


def _run(args: argparse.Namespace, diag: Diagnostics) -> int:
    if args.xsd:
        return _xsd(args, diag)
    from miro_gen.codegen.generate import changed_files, write_files
    from miro_gen.params.compiler import generate
    from miro_gen.params.compiler.pymodel import PyParamsModule

    modules = [
        m
        for m in compile_files(
            args.files,
            args.include_dirs,
            args.name,
            diag,
            args.python_classes,
            args.skip_untranslatable,
        )
        if isinstance(m, PyParamsModule)
    ]
    diag.print()
    if diag.has_errors:
        return 1
    outdir = Path(args.outdir)
    files = generate.generated_files(modules, outdir)
    changed = changed_files(files, outdir)
    if args.check:
        for rel in changed:
            print(f"miro-params: {outdir / rel} is out of date", file=sys.stderr)
        return 1 if changed else 0
    try:
        write_files(files, changed, outdir)
    except OSError as e:
        where = e.filename or outdir
        why = (
            "a file is in the way of a folder"
            if isinstance(e, (FileExistsError, NotADirectoryError))
            else e.strerror or str(e)
        )
        print(f"miro-params: cannot write '{where}': {why}", file=sys.stderr)
        return 1
    for rel in changed:
        print(f"wrote {outdir / rel}")
    if not changed:
        print(f"miro-params: {len(files)} files in {outdir} are up to date")
    return 0


def _xsd(args: argparse.Namespace, diag: Diagnostics) -> int:
    from miro_gen.params.compiler import dynamic
    from miro_gen.params.compiler.xsd import render_xsd

    classes = dynamic.load(args.files, args.include_dirs, diag, args.python_classes)
    diag.print()
    sys.stdout.write(render_xsd(c.cls for c in classes if c.target))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
