"""miro-idl against omniidl on whole trees of real IDL, file by file.

- Debian's omniORB tree (`/usr/share/idl/omniORB`, package omniorb-idl, installed by .ci/run):
  the ORB's own IDL (corbaidl.idl, ir.idl, orb.idl, poa.idl...) and the CORBA services in COS/
  (naming, events, notification with its filters, properties, life cycle, relationships, graphs,
  collections, trading, security...), compiled as omniidl compiles them, with
  `-I /usr/share/idl/omniORB -I /usr/share/idl/omniORB/COS`;
- the project's own idl/, with `-I idl`.

Every file must agree (tests/idl_differential.py): both accept it with the same declarations, or
both reject it. Files omniidl rejects in the omniORB tree (ten: missing IOP.idl, undeclared
CORBA::ServiceOption and CORBA::Environment) must be rejected with `file:line:col: error:`.

Generation: every file of the omniORB tree that miro-idl accepts either generates Python, or is
refused with `file:line:col: error:` naming the construct (`any`, TypeCode, value types, or an
included file that uses them); all that generates, compiled in one run, imports and passes ruff
and mypy --strict. (Naming.idl repeats CosNaming.idl's declarations: the two cannot share a
run, which tests/codegen/test_generation_limits.py checks.)

Skipped, with the reason, where omniidl or the omniORB tree is not installed.
"""

from __future__ import annotations

import re
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from pathlib import Path
from typing import Any

import generated_checks as G
import pytest
from idl_differential import REPO, compare_file, idl_files, omniidl_results, omniidl_unavailable
from miro_cli import run_miro_idl

OMNIORB_IDL = Path("/usr/share/idl/omniORB")

SKIP_REASON = omniidl_unavailable()
needs_omniidl = pytest.mark.skipif(SKIP_REASON is not None, reason=SKIP_REASON or "")

TREES: dict[str, tuple[Path, list[Path]]] = {
    "omniORB": (OMNIORB_IDL, [OMNIORB_IDL, OMNIORB_IDL / "COS"]),
    "project": (REPO / "idl", [REPO / "idl"]),
}


# Files written in IDL 4 (the integer types of rosidl: uint8, int64...), which omniidl, an IDL 3
# compiler, does not know (it reports 'uint8' not found, then its C++ back end crashes).
IDL4_ONLY = {REPO / "idl" / "rmw_dds_common.idl"}


def _files(tree: str) -> list[Any]:
    root, _ = TREES[tree]
    return [
        pytest.param(
            p,
            id=f"{tree}/{p.relative_to(root)}",
            marks=[pytest.mark.skip(reason="IDL 4 types, which omniidl does not know")]
            if p in IDL4_ONLY
            else [],
        )
        for p in idl_files(root)
    ]


@cache
def _omniidl(tree: str) -> dict[str, dict[str, Any]]:
    root, includes = TREES[tree]
    files = [str(p) for p in idl_files(root) if p not in IDL4_ONLY]
    return omniidl_results(files, [str(d) for d in includes])


def _check(tree: str, path: Path) -> None:
    _, includes = TREES[tree]
    verdict = compare_file(str(path), [str(d) for d in includes], _omniidl(tree)[str(path)])
    assert verdict.agree, f"{verdict.summary}:\n" + "\n".join(verdict.problems)


@needs_omniidl
@pytest.mark.skipif(not OMNIORB_IDL.is_dir(), reason="omniorb-idl is not installed")
@pytest.mark.parametrize("path", _files("omniORB") if OMNIORB_IDL.is_dir() else [])
def test_omniorb_tree_agrees(path: Path) -> None:
    _check("omniORB", path)


@needs_omniidl
@pytest.mark.parametrize("path", _files("project"))
def test_project_idl_agrees(path: Path) -> None:
    _check("project", path)


@needs_omniidl
@pytest.mark.skipif(not OMNIORB_IDL.is_dir(), reason="omniorb-idl is not installed")
def test_omniorb_tree_is_mostly_accepted() -> None:
    """A guard against a tree that both compilers reject wholesale (a wrong include path):
    omniidl accepts 61 of its 71 files today."""
    results = _omniidl("omniORB")
    accepted = sum(r["ok"] for r in results.values())
    assert accepted >= 0.8 * len(results), f"omniidl accepts only {accepted} of {len(results)}"


ERROR_LINE = re.compile(r"^(?P<path>/.+?\.idl):\d+:\d+: error: .+$")


@pytest.mark.skipif(not OMNIORB_IDL.is_dir(), reason="omniorb-idl is not installed")
def test_omniorb_tree_generates_or_is_refused(tmp_path: Path) -> None:
    _, includes = TREES["omniORB"]
    inc = [arg for d in includes for arg in ("-I", str(d))]
    files = [p for p in idl_files(OMNIORB_IDL) if p.name != "Naming.idl"]

    def alone(path: Path) -> tuple[Path, bool, str]:
        accepted = run_miro_idl(*inc, "--ast-json", str(path)).returncode == 0
        out = run_miro_idl(*inc, "-o", str(tmp_path / "one" / path.stem), str(path))
        return path, accepted, out.stderr if out.returncode else ""

    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(alone, files))
    generated = []
    for path, accepted, refusal in results:
        if not accepted:
            continue
        if not refusal:
            generated.append(path)
            continue
        errors = [line for line in refusal.splitlines() if ": error: " in line]
        assert errors and all(ERROR_LINE.match(e) for e in errors), f"{path}:\n{refusal}"
        assert "Traceback" not in refusal and "internal error" not in refusal, refusal
    assert len(generated) >= 15, [p.name for p in generated]
    out_dir = tmp_path / "all"
    out = run_miro_idl(*inc, "-o", str(out_dir), *map(str, generated))
    assert out.returncode == 0, out.stderr
    assert not G.import_problems(out_dir)
    assert not G.ruff_problems(out_dir)
    assert not G.mypy_problems(out_dir, tmp_path / "mypy-cache")
