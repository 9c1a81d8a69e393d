"""`miro build`: make a project's `generated/` what its IDL and parameter files make today
(miro_gen.cli.freshness); `--check` only says whether it is."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from miro_gen.cli.freshness import StaleError, check, ensure_fresh, find_project


def build_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro build",
        description="Regenerate the project's generated/ from its IDL (idl/*.idl) and "
        "parameter files (params/*.xml, services/*/*Parameters.xml) when they changed since "
        "it was made. miro run and miro launch do the same before they start anything.",
    )
    p.add_argument("folder", nargs="?", default=".", help="the project (default: this folder)")
    p.add_argument(
        "--check", action="store_true", help="change nothing; exit 1 when generated/ is stale"
    )
    ns = p.parse_args(argv)
    project = find_project(Path(ns.folder))
    if project is None:
        print(
            f"miro build: {Path(ns.folder).resolve()} is not in a project (a folder with "
            "generated/ and idl/*.idl or parameter files)",
            file=sys.stderr,
        )
        return 1
    if ns.check:
        state = check(project)
        for line in state.errors + state.stale:
            print(line, file=sys.stderr)
        if not state.fresh:
            print(f"miro build: run {project.command_text()}", file=sys.stderr)
        return 0 if state.fresh else 1
    try:
        wrote = ensure_fresh(project)
    except StaleError as e:
        print(f"miro build: {e}", file=sys.stderr)
        return 1
    for line in wrote:
        print(line)
    print(f"{project.generated}: up to date" if not wrote else f"regenerated {len(wrote)} files")
    return 0
