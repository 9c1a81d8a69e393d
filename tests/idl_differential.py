"""miro-idl against omniidl (Debian's CORBA IDL front end), file by file, on any IDL.

Shared by tests/idl/test_differential_omniidl.py (the corpus in tests/corpus/) and
tests/idl/test_real_idl.py (whole trees of real IDL: Debian's omniORB tree, the project's idl/), and
runnable on its own over any tree, for checking real IDL that is not committed:

    python tests/idl_differential.py [-I DIR]... [--tree-includes] [-v] PATH...

Each PATH is an IDL file or a folder searched for `*.idl`. `--tree-includes` adds every folder
of each PATH that holds IDL to the include path (real trees include `<orbsvcs/X.idl>` and
`"X.idl"` from sibling folders). Prints one verdict per file and the agreement rate.

A file agrees when both compilers accept it with the same declarations (kinds, scoped names,
repository ids, files, lines, order and per-kind fields: members, types, dims, union
discriminators and labels, enumerators, constants, bases, operations, attributes, value types),
or when both reject it. omniidl runs through tests/omniidl_dump.py under the system Python.

Not compared, on purpose: `doc` (omniidl has no doc comments in miro-idl's sense),
`annotations` (omniidl has no IDL 4 annotations), attribute `get_raises`/`set_raises`
(omniidl 4.2 has no getraises/setraises). Compared loosely: `file` by basename, floating-point
constants with a relative tolerance of 1e-6 (omniidl keeps `float` constants in single
precision), fixed-point values numerically (omniidl drops trailing zeros).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
DUMP = TESTS / "omniidl_dump.py"
# The Python omniidl is built for (Debian: the system one); override with MIRO_OMNIIDL_PYTHON.
OMNIIDL_PYTHON = os.environ.get("MIRO_OMNIIDL_PYTHON", "/usr/bin/python3")

NOT_COMPARED = ("doc", "annotations")


def omniidl_unavailable() -> str | None:
    """Why omniidl's front end cannot run here, or None."""
    if not Path(OMNIIDL_PYTHON).exists():
        return f"{OMNIIDL_PYTHON} not found (omniidl's front end needs the system Python)"
    if shutil.which("omnicpp") is None:
        return "omnicpp (omniidl's preprocessor) is not installed: apt-get install omniidl"
    try:
        proc = subprocess.run(
            [OMNIIDL_PYTHON, str(DUMP), "--probe"], capture_output=True, text=True, timeout=60
        )
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"cannot run {OMNIIDL_PYTHON}: {e}"
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return f"{OMNIIDL_PYTHON} cannot import omniidl (apt-get install omniidl): {last}"
    return None


def omniidl_results(
    files: list[str], include_dirs: list[str], cwd: Path | None = None
) -> dict[str, dict[str, Any]]:
    """omniidl's verdict on each file (one run of tests/omniidl_dump.py), keyed as given."""
    cmd = [OMNIIDL_PYTHON, str(DUMP)]
    for d in include_dirs:
        cmd += ["-I", d]
    cmd += files
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise RuntimeError(f"omniidl_dump failed:\n{proc.stderr}")
    results: dict[str, dict[str, Any]] = json.loads(proc.stdout)
    return results


def miro_result(path: str, include_dirs: list[str]) -> tuple[dict[str, Any] | None, list[Any]]:
    """miro-idl's AST JSON document for one file (None when rejected) and its diagnostics."""
    from miro_gen.diagnostics import CompileError, Diagnostics
    from miro_gen.idl import compile_idl
    from miro_gen.idl.ast_json import dumps, specifications_json

    diag = Diagnostics()
    try:
        spec = compile_idl(path, include_dirs, {}, diag)
    except CompileError:
        return None, diag.items
    return json.loads(dumps(specifications_json([path], [spec]))), diag.items


# ---- normalisation and comparison -------------------------------------------------------


def normalise(decl: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in decl.items() if k not in NOT_COMPARED}
    out["file"] = os.path.basename(out["file"])
    if "members" in out:
        out["members"] = [
            {k: v for k, v in m.items() if k != "annotations"} for m in out["members"]
        ]
    if "attributes" in out:
        out["attributes"] = [
            {k: v for k, v in a.items() if k not in ("get_raises", "set_raises")}
            for a in out["attributes"]
        ]
    return out


def _unaliased(type_name: str, by_name: dict[str, dict[str, Any]]) -> str:
    seen = set()
    while type_name in by_name and by_name[type_name]["kind"] == "typedef":
        if type_name in seen:  # pragma: no cover - cycles are rejected by both compilers
            break
        seen.add(type_name)
        type_name = by_name[type_name]["type"]
    return type_name


def _const_values_equal(type_name: str, a: Any, b: Any) -> bool:
    if type_name.startswith("fixed"):
        try:
            return isinstance(a, str) and isinstance(b, str) and Decimal(a) == Decimal(b)
        except InvalidOperation:
            return False
    if type_name in ("float", "double", "long double"):
        return (
            isinstance(a, float)
            and isinstance(b, float)
            and math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-300)
        )
    return type(a) is type(b) and a == b


def differences(
    miro: dict[str, Any], omni: dict[str, Any], by_name: dict[str, dict[str, Any]]
) -> list[str]:
    """The fields where two normalised declarations differ."""
    out = []
    for key in sorted(set(miro) | set(omni)):
        if key not in miro or key not in omni:
            out.append(f"{key}: only in {'miro-idl' if key in miro else 'omniidl'}")
            continue
        a, b = miro[key], omni[key]
        if key == "value" and miro["kind"] == "const":
            if not _const_values_equal(_unaliased(miro["type"], by_name), a, b):
                out.append(f"value: miro-idl {a!r} != omniidl {b!r}")
        elif json.dumps(a, sort_keys=True) != json.dumps(b, sort_keys=True):
            out.append(f"{key}: miro-idl {json.dumps(a)} != omniidl {json.dumps(b)}")
    return out


def _key(d: dict[str, Any]) -> str:
    return f"{d['kind']} {d['name']} ({d['file']})"


def _line_problem(miro: dict[str, Any], omni: dict[str, Any]) -> str | None:
    """miro-idl gives the line of a declaration's name; omniidl the line where its parser
    finished the declaration's head (the line of a struct's `{`, a union's `switch`, a
    constant's `=`), which is never earlier."""
    if miro["line"] <= omni["line"]:
        return None
    return f"line: miro-idl {miro['line']} is after omniidl's {omni['line']}"


def declaration_problems(
    mine_decls: list[dict[str, Any]], omni_decls: list[dict[str, Any]]
) -> list[str]:
    """Why two accepted files' declarations differ (empty when they agree)."""
    mine = [normalise(d) for d in mine_decls]
    theirs = [normalise(d) for d in omni_decls]
    mine_keys = [_key(d) for d in mine]
    their_keys = [_key(d) for d in theirs]
    if mine_keys != their_keys:
        only_mine = [k for k in mine_keys if k not in set(their_keys)]
        only_theirs = [k for k in their_keys if k not in set(mine_keys)]
        problems = ["declarations differ (kind, name, file, line or order)"]
        problems += [f"  only miro-idl: {k}" for k in only_mine[:10]]
        problems += [f"  only omniidl: {k}" for k in only_theirs[:10]]
        if not only_mine and not only_theirs:
            problems.append("  same declarations in a different order")
        return problems
    by_name = {d["name"]: d for d in mine}
    problems = []
    for m, o in zip(mine, theirs, strict=True):
        line = _line_problem(m, o)
        if line is not None:
            problems.append(f"{_key(m)}: {line}")
        m, o = dict(m, line=0), dict(o, line=0)
        problems += [f"{_key(m)}: {diff}" for diff in differences(m, o, by_name)]
    return problems


def errors_text(result: dict[str, Any]) -> str:
    return "\n".join(f"{e['file']}:{e['line']}: {e['message']}" for e in result["errors"])


@dataclass
class Verdict:
    """One file's comparison: `agree` and, when they disagree, why."""

    path: str
    agree: bool
    summary: str
    problems: list[str] = field(default_factory=list)


def compare_file(path: str, include_dirs: list[str], omni: dict[str, Any]) -> Verdict:
    doc, items = miro_result(path, include_dirs)
    errors = [str(d) for d in items if d.severity == "error"]
    if omni["ok"] and doc is not None:
        problems = declaration_problems(doc["declarations"], omni["declarations"])
        if problems:
            return Verdict(path, False, "both accept, declarations differ", problems)
        return Verdict(path, True, "both accept, same declarations")
    if not omni["ok"] and doc is None:
        first = next((d for d in items if d.severity == "error" and d.pos is not None), None)
        mine_at = f"{os.path.basename(first.pos.path)}:{first.pos.line}" if first else "?"
        theirs_at = {f"{e['file']}:{e['line']}" for e in omni["errors"]}
        where = "" if mine_at in theirs_at else f" (miro-idl's first error at {mine_at})"
        return Verdict(path, True, "both reject" + where, [*errors[:3], errors_text(omni)])
    if omni["ok"]:
        return Verdict(path, False, "only omniidl accepts", errors[:10])
    return Verdict(path, False, "only miro-idl accepts", errors_text(omni).splitlines()[:10])


def compare_files(files: list[str], include_dirs: list[str]) -> list[Verdict]:
    omni = omniidl_results(files, include_dirs)
    return [compare_file(f, include_dirs, omni[f]) for f in files]


def idl_files(root: Path) -> list[Path]:
    if root.is_file():
        return [root]
    return sorted(p for p in root.rglob("*.idl") if p.is_file())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("paths", nargs="+", type=Path, metavar="PATH")
    p.add_argument("-I", dest="include_dirs", action="append", default=[], metavar="DIR")
    p.add_argument("--tree-includes", action="store_true", help="-I every folder holding IDL")
    p.add_argument("-v", "--verbose", action="store_true", help="say why files disagree")
    args = p.parse_args(argv)
    why = omniidl_unavailable()
    if why:
        print(f"idl_differential: {why}", file=sys.stderr)
        return 2
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 20_000))
    include_dirs = list(args.include_dirs)
    files: list[str] = []
    for root in args.paths:
        found = idl_files(root)
        files += [str(f) for f in found]
        if args.tree_includes:
            for d in sorted({str(f.parent) for f in found}):
                if d not in include_dirs:
                    include_dirs.append(d)
    verdicts = compare_files(files, include_dirs)
    agree = 0
    for v in verdicts:
        agree += v.agree
        print(f"{'ok  ' if v.agree else 'DIFF'} {v.path}: {v.summary}")
        if args.verbose and (not v.agree or "first error" in v.summary):
            for line in v.problems:
                print(f"       {line}")
    total = len(verdicts)
    rate = 100.0 * agree / total if total else 100.0
    print(f"{agree}/{total} files agree ({rate:.1f}%)")
    return 0 if agree == total else 1


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
