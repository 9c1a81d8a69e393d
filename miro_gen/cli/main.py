"""`miro`: the umbrella command; its verbs are the table of cli/verbs.py."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from miro_gen.cli import verbs
from miro_gen.cli.common import VersionAction, piped


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro",
        description="miro-gen: Miro (Middleware for Robots) in Python.",
        epilog="The IDL compiler is `miro-idl` (also `miro idl`), the parameter compiler "
        "`miro-params` (also `miro params`); see their --help.",
    )
    p.add_argument("--version", action=VersionAction)
    verbs.listed(p, verbs.VERBS)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run a sub-command; 130 after Ctrl-C (128 + the signal), without a traceback; quietly
    when the reader of its output goes away (`miro call ... | head`)."""
    try:
        return piped(dispatch, list(sys.argv[1:] if argv is None else argv))
    except KeyboardInterrupt:
        from miro_gen import lifecycle

        return lifecycle.exit_status()


def dispatch(args: list[str]) -> int:
    """Run the verb `args[0]` names (cli/verbs.py); else `miro`'s own help or usage error."""
    verb = verbs.find(args[0]) if args else None
    if verb is not None:
        return verbs.run(verb, args[1:], f"miro {verb.name}")
    parser = build_parser()
    parser.parse_args(args)  # --help, --version, or an unknown verb: it exits
    parser.print_help()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
