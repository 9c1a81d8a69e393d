"""The IDL corpus (tests/corpus/, described in tests/idl_corpus.py) through miro-idl.

- valid and idl4 files compile without errors, with exactly their `// expect-warning:`
  warnings, and their AST JSON contains every `// check:` fragment;
- invalid files produce exactly their `// expect:` errors through the Python API, and through
  the command line exit with status 1, print nothing on stdout and report the errors on stderr
  as `path:line:col: error: message`, without a traceback.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from pathlib import Path

import pytest
from idl_corpus import (
    INCLUDE_DIR,
    REPO,
    Expected,
    compile_corpus_file,
    corpus_files,
    find_declaration,
    fragment_mismatch,
    params,
    parse_directives,
    repo_relative,
)

from miro_gen.diagnostics import Diagnostic


def _describe(items: list[Diagnostic]) -> str:
    return "\n".join(str(d) for d in items) or "(no diagnostics)"


def _match_exactly(
    kind: str, expected: list[Expected], got: list[Diagnostic], allow_more: bool
) -> list[str]:
    """Problems matching `expected` one-to-one against the diagnostics `got` of one severity."""
    problems = []
    remaining = list(got)
    for exp in expected:
        for d in remaining:
            if d.pos is not None and exp.matches(d.pos.line, d.pos.col, d.message):
                remaining.remove(d)
                break
        else:
            problems.append(f"missing {kind} {exp}")
    if remaining and not allow_more:
        problems += [f"unexpected {kind} {d}" for d in remaining]
    return problems


@pytest.mark.parametrize("path", params("valid", "api") + params("idl4", "api"))
def test_accepted(path: Path) -> None:
    directives = parse_directives(path)
    assert not directives.errors, "an accepted file cannot expect errors"
    doc, items = compile_corpus_file(path)
    errors = [d for d in items if d.severity == "error"]
    assert doc is not None and not errors, _describe(items)
    warnings = [d for d in items if d.severity == "warning"]
    problems = _match_exactly("warning", directives.warnings, warnings, allow_more=False)
    assert not problems, "\n".join(problems) + "\n\nmiro-idl said:\n" + _describe(items)
    decls = doc["declarations"]
    assert decls, "no declarations"
    for name, fragment in directives.checks:
        decl = find_declaration(decls, name, fragment.get("kind"))
        why = fragment_mismatch(fragment, decl, name)
        assert why is None, f"{why}\n{json.dumps(decl, indent=1, ensure_ascii=False)}"


@pytest.mark.parametrize("path", params("invalid", "api"))
def test_rejected(path: Path) -> None:
    directives = parse_directives(path)
    assert directives.errors, "an invalid corpus file must say which errors it expects"
    doc, items = compile_corpus_file(path)
    errors = [d for d in items if d.severity == "error"]
    assert doc is None and errors, "accepted, but expected:\n" + "\n".join(
        str(e) for e in directives.errors
    )
    rel = repo_relative(path)
    for d in errors:  # every error points into the file (or names it, for a missing file)
        assert d.pos is not None and d.pos.path == rel, f"error without a position here: {d}"
        assert d.pos.line >= 1 and d.pos.col >= 1, d
    problems = _match_exactly("error", directives.errors, errors, directives.more)
    assert not problems, "\n".join(problems) + "\n\nmiro-idl said:\n" + _describe(items)


def test_corpus_is_complete() -> None:
    """Every category has files, and the files in each category are what they claim."""
    for kind in ("valid", "idl4", "invalid"):
        assert corpus_files(kind), f"no corpus files in tests/corpus/{kind}"
    for path in corpus_files("idl4"):
        assert parse_directives(path).checks, f"{path.name}: idl4 files check their AST JSON"


# ---- the command line -----------------------------------------------------------------------

_DIAG_LINE = re.compile(
    r"^(?P<path>[^:\n]+):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning|note): "
)


@cache
def _cli_results() -> dict[Path, subprocess.CompletedProcess[str]]:
    """`python -m miro_gen.cli.idl --ast-json FILE` for every invalid file (run in parallel)."""

    def run(path: Path) -> subprocess.CompletedProcess[str]:
        cmd = [sys.executable, "-m", "miro_gen.cli.idl", "-I", repo_relative(INCLUDE_DIR)]
        cmd += ["--ast-json", repo_relative(path)]
        return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)

    files = corpus_files("invalid")
    with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:
        return dict(zip(files, pool.map(run, files), strict=True))


@pytest.mark.parametrize("path", params("invalid", "cli"))
def test_rejected_by_cli(path: Path) -> None:
    proc = _cli_results()[path]
    out = f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    assert "Traceback" not in proc.stdout + proc.stderr, out
    assert "internal error" not in proc.stderr, out
    assert proc.returncode == 1, out
    assert proc.stdout == "", out
    rel = repo_relative(path)
    lines = proc.stderr.splitlines()
    assert lines, out
    for line in lines:
        m = _DIAG_LINE.match(line)
        assert m, f"not a `path:line:col: severity: message` line: {line!r}\n{out}"
        assert m["path"] == rel, f"diagnostic for another file: {line!r}"
    for exp in parse_directives(path).errors:
        prefix = f"{rel}:{exp.line}:{exp.col}: error: "
        assert any(ln.startswith(prefix) and exp.text in ln for ln in lines), (
            f"missing error {exp}\n{out}"
        )


def test_missing_include_names_the_search_path() -> None:
    path = next(p for p in corpus_files("invalid") if p.name == "missing_include.idl")
    proc = _cli_results()[path]
    assert "'does/not/exist.idl'" in proc.stderr, proc.stderr
    # the including file's folder first, then the -I folders
    assert f"(searched: {repo_relative(path.parent)}, {repo_relative(INCLUDE_DIR)})" in proc.stderr
