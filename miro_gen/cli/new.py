"""`miro new NAME` (scaffold a service in one of the manual's patterns) and `miro run NAME`."""

from __future__ import annotations

import argparse
import os
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
    print(
        f"\nnext:\n"
        f"  miro naming &                            # a naming service, if none runs\n"
        f"  miro run {args.name}                       # start it\n"
        f"  python -m pytest {args.dir}/{args.name}            # its test\n"
        f"  edit {args.dir}/{args.name}/ (see its README.md)"
    )
    return 0


def run_main(argv: Sequence[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(
            "usage: miro run NAME [ARGS...]\n\n"
            "Run the service DIR/NAME of the project in the current folder (DIR: services, or "
            "the MIRO_SERVICES environment variable) as `python -m DIR.NAME ARGS`, with the "
            "project's generated code on the path.",
            file=sys.stderr if not argv else sys.stdout,
        )
        return 2 if not argv else 0
    name, rest = argv[0], list(argv[1:])
    folder = os.environ.get("MIRO_SERVICES", "services")
    project = Path.cwd()
    if not (project / folder / name / "__main__.py").is_file():
        print(
            f"miro run: no service {name!r} in {project / folder} "
            f"(make one with `miro new {name}`)",
            file=sys.stderr,
        )
        return 1
    from miro_gen.cli.freshness import before_running

    if not before_running(project, "miro run"):  # never the old generated code
        return 1
    env = dict(os.environ)
    paths = [str(project / "generated"), str(project), env.get("PYTHONPATH", "")]
    env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
    sys.stdout.flush()
    os.execve(sys.executable, [sys.executable, "-m", f"{folder}.{name}", *rest], env)
    return 0  # pragma: no cover - execve does not return
