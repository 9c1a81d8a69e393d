"""Code generation is linear in its input: the work per declaration stays flat as IDL grows.

Work is counted, not timed: the Python and built-in function calls (cProfile's count, the same
on every run whatever the machine's load) of compiling and rendering IDL files of 8, 16 and 32
modules, each module like the next one (bench/gen_idl.py's modules, with names of one width, so
that no line grows longer with the module's number). Linear work adds the same amount per
module: the cost of modules 16-32 is twice that of modules 8-16. Something indexed once per
interface instead of once per compilation (issue 30: `interface_schema._Writer` re-indexed every
declaration for each interface, O(interfaces x declarations)) makes the second step cost more.
"""

from __future__ import annotations

import cProfile
import pstats
import re
import sys
from pathlib import Path

from repo_paths import REPO

from miro_gen.codegen import generate
from miro_gen.diagnostics import Diagnostics
from miro_gen.idl.frontend import compile_idl

sys.path.insert(0, str(REPO / "bench"))
from gen_idl import module

SIZES = (8, 16, 32)
SLACK = 1.01  # what the counts may grow beyond linear: dictionaries and caches filling up


def idl(modules: int) -> str:
    """`modules` modules of bench/gen_idl.py, numbered with four digits (M0007)."""
    text = "".join(module(i) for i in range(modules))
    return re.sub(r"\bM(\d+)\b", lambda m: f"M{int(m.group(1)):04d}", text)


def calls(path: Path, outdir: Path) -> tuple[int, int]:
    """Function calls of compiling `path` and rendering its files, and its declarations."""
    diag = Diagnostics()
    profile = cProfile.Profile()
    profile.enable()
    spec = compile_idl(str(path), [], {}, diag)
    modules = generate.build_modules([(spec, str(path))], diag)
    files = generate.generated_files(modules, outdir)
    profile.disable()
    assert not diag.has_errors and files
    return pstats.Stats(profile).total_calls, len(spec.declarations)  # type: ignore[attr-defined]


def test_work_per_declaration_stays_flat_as_the_idl_grows(tmp_path: Path) -> None:
    warm = tmp_path / "warm.idl"  # imports, grammar tables and templates loaded beforehand
    warm.write_text(idl(2))
    calls(warm, tmp_path / "warm")
    work: list[int] = []
    declarations: list[int] = []
    for n in SIZES:
        path = tmp_path / f"m{n}.idl"
        path.write_text(idl(n))
        w, d = calls(path, tmp_path / f"out{n}")
        work.append(w)
        declarations.append(d)
    assert declarations[2] - declarations[1] == 2 * (declarations[1] - declarations[0])
    first, second = work[1] - work[0], work[2] - work[1]
    per_decl = [w / d for w, d in zip(work, declarations, strict=True)]
    assert second <= 2 * first * SLACK, (
        f"modules {SIZES[1]}-{SIZES[2]} cost {second} calls, {second / first:.3f}x those of "
        f"modules {SIZES[0]}-{SIZES[1]} ({first}): work grows faster than the input "
        f"(calls per declaration: {', '.join(f'{p:.0f}' for p in per_decl)})"
    )
