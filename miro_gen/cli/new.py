"""`miro new NAME`: scaffold a service in one of the manual's patterns."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from miro_gen.scaffold.patterns import PATTERNS


def new_main(argv: Sequence[str]) -> int:
    patterns = "\n".join(f"  {name:11} {p.doc}" for name, p in PATTERNS.items())
    p = argparse.ArgumentParser(
        prog="miro new",
        description="Scaffold a service in one of the Miro manual's design patterns: its files "
        "under DIR/NAME, its parameters (compiled with miro-params), a README and a test that "
        "runs it against a naming service. Run it with `miro run NAME`.",
        epilog="patterns:\n" + patterns,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", help="the service's name: lower case, digits, underscores")
    p.add_argument("--pattern", choices=list(PATTERNS), default="basic", help="default: basic")
    p.add_argument("--interface", help="the IDL interface served or polled (Module::Name)")
    p.add_argument("--idl", type=Path, help="compile this IDL file first (for --interface)")
    p.add_argument("-I", dest="include_dirs", action="append", default=[], metavar="DIR",
                   help="#include search path for --idl")  # fmt: skip
    p.add_argument("--dir", default="services", help="the folder of services (default services)")
    args = p.parse_args(argv)
    if args.idl is not None and not args.interface:
        p.error("--idl needs --interface, the interface of that file to use")
    if not args.dir.isidentifier():
        p.error("--dir must be a folder name that is a Python identifier (services)")
    from miro_gen.scaffold.generate import ScaffoldError, compile_idl, scaffold

    project = Path.cwd()
    generated = project / "generated"  # the project's own IDL packages, for --interface
    if generated.is_dir() and str(generated) not in sys.path:
        sys.path.insert(0, str(generated))
    try:
        if args.idl is not None:
            if not args.idl.is_file():
                p.error(f"{args.idl}: no such file")
            compile_idl(args.idl, project, args.include_dirs)
        written = scaffold(
            args.name, args.pattern, project=project, folder=args.dir, interface=args.interface
        )
    except ScaffoldError as e:
        print(f"miro new: {e}", file=sys.stderr)
        return 1
    for path in written:
        print(f"wrote {path.relative_to(project)}")
    steps = [
        ("miro naming &", "a naming service, if none runs"),
        (f"miro run {args.name}", "start it"),
        (f"python -m pytest {args.dir}/{args.name}", "its test"),
        (f"edit {args.dir}/{args.name}/", "see its README.md"),
    ]
    width = max(len(command) for command, _ in steps) + 2
    print("\nnext:")
    for command, why in steps:
        print(f"  {command:<{width}}# {why}")
    return 0
