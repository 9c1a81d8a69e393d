"""`python -m miro_gen.compile [--cpu S] [--memory BYTES] FOLDER`: compile the schema from
elsewhere in FOLDER/schema.idl into FOLDER/py and FOLDER/ast.json, as foreign.py asks. The
limits are set first, before any compiler is imported; the problem, if any, is the first line
on standard error and the status is 1."""

from __future__ import annotations

import argparse
import errno
import os
import resource
import sys
from collections.abc import Sequence
from pathlib import Path


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m miro_gen.compile", description=__doc__)
    p.add_argument("--cpu", type=int, help="seconds of CPU time at most")
    p.add_argument("--memory", type=int, help="bytes of address space at most")
    p.add_argument("folder", type=Path)
    ns = p.parse_args(argv)
    if ns.memory:
        resource.setrlimit(resource.RLIMIT_AS, (ns.memory, ns.memory))
    if ns.cpu:
        resource.setrlimit(resource.RLIMIT_CPU, (ns.cpu, ns.cpu))
    if ns.memory or ns.cpu:  # stopped at a limit: no core file left behind
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    try:
        return _compile(ns.folder)
    except (MemoryError, OSError, ImportError) as e:
        if not ns.memory or not _out_of_memory(e):
            raise
        # Said so, in one line, whatever ran out: the caller tells a limit from a defect by it.
        what = "" if isinstance(e, MemoryError) else f"{type(e).__name__}: "
        print(f"MemoryError: {what}{e}", file=sys.stderr)
        return 1


def _out_of_memory(e: BaseException) -> bool:
    """Whether `e` is the address-space limit met: Python's MemoryError, or an allocation or a
    shared library's mapping the kernel refused (ENOMEM)."""
    if isinstance(e, MemoryError):
        return True
    if isinstance(e, OSError) and e.errno == errno.ENOMEM:
        return True
    text = str(e).lower()
    return "memory" in text or "map segment" in text or "mmap" in text


def _compile(folder: Path) -> int:
    from miro_gen.compile import foreign

    text = (folder / foreign.SOURCE).read_text(encoding="utf-8")
    why = foreign.refusal(text)  # whoever started this process: the same policy
    if why is not None:
        print(why, file=sys.stderr)
        return 1
    from miro_gen.compile.idl import idl_package
    from miro_gen.idl.ast_json import dumps, specifications_json

    source = os.path.relpath(folder / foreign.SOURCE)  # problems name `schema.idl`
    done = idl_package([source], folder / foreign.PACKAGES, base=folder)
    problems = [str(d) for d in done.diagnostics if d.severity == "error"] + done.errors
    if problems:
        print("\n".join(problems), file=sys.stderr)
        return 1
    ast = dumps(specifications_json([foreign.SOURCE], done.specs))
    (folder / foreign.AST).write_text(ast, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
