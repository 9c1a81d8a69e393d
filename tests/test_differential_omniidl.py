"""miro-idl against omniidl, Debian's CORBA IDL front end, on the corpus in tests/corpus/.

tests/omniidl_dump.py runs omniidl's own front end (omnicpp + `_omniidl.compile`) under the system
Python that omniidl is built for, and prints each file's declarations in miro-idl's `--ast-json`
shape. It runs once for the whole corpus (module-level cache).

- valid/: both accept, and the declarations are equal: same kinds, scoped names, repository
  ids, files, lines and order, and the same per-kind fields (members, types, array dims, union
  discriminators and labels, enumerators, typedefs, constant types and values, interface bases,
  operations, parameters, raises, contexts, attributes, forward declarations, natives,
  exceptions, value types with their state members, factories and boxes).
  Not compared, on purpose:
    * `doc`: omniidl keeps comments only with -K and attaches every comment, not just doc
      comments (`//!`, `///`, `/** */`); tests/test_corpus.py checks doc strings instead;
    * `annotations`: omniidl has no IDL 4 annotations (files using them are in idl4/);
    * attribute `get_raises`/`set_raises`: omniidl 4.2 has no getraises/setraises (always
      empty on its side; idl4/corba3_extras.idl covers them);
    * `files`: both list the command-line file, written identically;
  and compared loosely: `file` by basename (omniidl reports the path as its preprocessor wrote
  it), floating-point constant values with a relative tolerance of 1e-6 (omniidl keeps `float`
  constants in single precision, `long double` in double), fixed-point values numerically
  (omniidl drops trailing zeros: 1.50d is "1.5").
  Lines are compared exactly, so the corpus keeps each declaration on one line: for a struct,
  interface or value type omniidl records the line of its `{`, miro-idl the line of its name.
- idl4/: miro-idl accepts these and omniidl must reject them; IDL4_REASONS says why for each
  (an IDL 4 feature, a CORBA 3 construct omniidl lacks, or a value omniidl gets wrong).
- invalid/: omniidl must reject them too, with an error on every line where the file expects
  one, except for the documented OMNIIDL_DIVERGENCES (where miro-idl is stricter or omniidl is
  wrong).

Skipped, with the reason, when /usr/bin/python3 (or $MIRO_OMNIIDL_PYTHON) cannot import omniidl's
front end.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from decimal import Decimal, InvalidOperation
from functools import cache
from pathlib import Path
from typing import Any

import pytest
from idl_corpus import (
    INCLUDE_DIR,
    REPO,
    TESTS,
    compile_corpus_file,
    corpus_files,
    corpus_id,
    params,
    parse_directives,
    repo_relative,
)

# The Python omniidl is built for (Debian: the system one); override with MIRO_OMNIIDL_PYTHON.
OMNIIDL_PYTHON = os.environ.get("MIRO_OMNIIDL_PYTHON", "/usr/bin/python3")
DUMP = TESTS / "omniidl_dump.py"

# Why omniidl rejects each idl4/ file (all of them must be listed).
IDL4_REASONS: dict[str, str] = {
    "idl4/annotations.idl": "IDL 4 annotations (omniidl aborts on them)",
    "idl4/user_annotations.idl": "IDL 4 @annotation declarations and user annotations",
    "idl4/int_types.idl": "IDL 4 int8/uint8/int16/.../uint64 (omniidl aborts on them)",
    "idl4/maps.idl": "IDL 4 map<K, V[, N]>",
    "idl4/struct_inheritance.idl": "IDL 4 struct inheritance and empty structs",
    "idl4/templates.idl": "IDL 4 `>>` closing nested templates, anonymous types as parameters",
    "idl4/discriminators.idl": "IDL 4 wchar and octet union discriminators",
    "idl4/corba3_extras.idl": "CORBA 3 getraises/setraises and typeid, which omniidl lacks",
    "idl4/typeprefix.idl": "CORBA 3 typeprefix, which omniidl lacks",
    "idl4/corba_constants.idl": (
        "omniidl is wrong: it rejects `~5` for long, `~0` for short and unsigned short and the "
        "most negative long/long long (`-2147483648`, `-2147483647 - 1`), which CORBA 3.0 "
        "section 3.10.2 defines (~x is -(x+1) for signed, 65535 for ~0 as unsigned short)"
    ),
}


# invalid/ files where omniidl's verdict differs from miro-idl's:
#   accepts=True: omniidl accepts the whole file;
#   otherwise `unflagged` lists the lines with an expected error where omniidl reports none.
class Divergence:
    def __init__(self, reason: str, accepts: bool = False, unflagged: frozenset[int] = frozenset()):
        self.reason = reason
        self.accepts = accepts
        self.unflagged = unflagged


OMNIIDL_DIVERGENCES: dict[str, Divergence] = {
    "invalid/const_float_range.idl": Divergence(
        "omniidl is wrong: it accepts floating-point constants beyond their type's range "
        "(`const float F = 1e40;` becomes inf)",
        accepts=True,
    ),
    "invalid/const_shift_overflow.idl": Divergence(
        "omniidl is wrong: it computes `1 << 32` in 32 bits for a long constant (giving 1) "
        "instead of rejecting 4294967296",
        unflagged=frozenset({3}),
    ),
    "invalid/constant_as_type.idl": Divergence(
        "omniidl is wrong: it accepts a constant's name as a member and parameter type",
        accepts=True,
    ),
    "invalid/valuetype_truncatable_abstract.idl": Divergence(
        "miro-idl is stricter: omniidl accepts `truncatable` with only an abstract base, "
        "although there is no concrete base to truncate to (CORBA 3.0 section 3.9.5)",
        accepts=True,
    ),
    "invalid/pragma_errors.idl": Divergence(
        "omniidl reports problems in a #pragma on the line after it",
        unflagged=frozenset({5, 8}),
    ),
}


def _probe() -> str | None:
    """Why the differential tests cannot run, or None."""
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


SKIP_REASON = _probe()
needs_omniidl = pytest.mark.skipif(SKIP_REASON is not None, reason=SKIP_REASON or "")


@cache
def omniidl_results() -> dict[str, dict[str, Any]]:
    """omniidl's verdict on every corpus file, keyed by corpus id (one run for the corpus)."""
    files = [p for kind in ("valid", "idl4", "invalid") for p in corpus_files(kind)]
    cmd = [OMNIIDL_PYTHON, str(DUMP), "-I", repo_relative(INCLUDE_DIR)]
    cmd += [repo_relative(p) for p in files]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    raw = json.loads(proc.stdout)
    return {corpus_id(p): raw[repo_relative(p)] for p in files}


def _omniidl(path: Path) -> dict[str, Any]:
    return omniidl_results()[corpus_id(path)]


def _errors_text(result: dict[str, Any]) -> str:
    return "\n".join(f"{e['file']}:{e['line']}: {e['message']}" for e in result["errors"])


# ---- normalisation and comparison -------------------------------------------------------

NOT_COMPARED = ("doc", "annotations")


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


# ---- the tests ----------------------------------------------------------------------------


@needs_omniidl
@pytest.mark.parametrize("path", params("valid", "diff"))
def test_valid_matches_omniidl(path: Path) -> None:
    omni = _omniidl(path)
    assert omni["ok"], "omniidl rejects a valid/ corpus file:\n" + _errors_text(omni)
    doc, items = compile_corpus_file(path)
    assert doc is not None, "miro-idl rejects it:\n" + "\n".join(str(d) for d in items)
    mine = [normalise(d) for d in doc["declarations"]]
    theirs = [normalise(d) for d in omni["declarations"]]

    def key(d: dict[str, Any]) -> str:
        return f"{d['kind']} {d['name']} ({d['file']}:{d['line']})"

    assert [key(d) for d in mine] == [key(d) for d in theirs], (
        "declarations differ (kind, name, file, line or order)"
    )
    by_name = {d["name"]: d for d in mine}
    problems = []
    for m, o in zip(mine, theirs, strict=True):
        for diff in differences(m, o, by_name):
            problems.append(f"{key(m)}: {diff}")
    assert not problems, "\n".join(problems)


@needs_omniidl
@pytest.mark.parametrize("path", params("idl4", "diff"))
def test_idl4_is_beyond_omniidl(path: Path) -> None:
    assert corpus_id(path) in IDL4_REASONS, "say in IDL4_REASONS why omniidl rejects this file"
    omni = _omniidl(path)
    assert not omni["ok"], (
        "omniidl accepts this idl4/ file: move it to valid/ so that it is compared"
    )


@needs_omniidl
@pytest.mark.parametrize("path", params("invalid", "diff"))
def test_invalid_rejected_by_omniidl(path: Path) -> None:
    omni = _omniidl(path)
    divergence = OMNIIDL_DIVERGENCES.get(corpus_id(path))
    if divergence is not None and divergence.accepts:
        assert omni["ok"], (
            f"documented as accepted by omniidl ({divergence.reason}), but it rejects it now:\n"
            + _errors_text(omni)
        )
        return
    assert not omni["ok"], "omniidl accepts this invalid/ file"
    expected_lines = {e.line for e in parse_directives(path).errors}
    flagged = {e["line"] for e in omni["errors"] if e["file"] == path.name}
    unflagged = expected_lines - flagged
    documented = divergence.unflagged if divergence is not None else frozenset()
    assert unflagged == documented, (
        f"lines with an expected error where omniidl reports none: {sorted(unflagged)}"
        f" (documented: {sorted(documented)})\nomniidl said:\n" + _errors_text(omni)
    )


def test_divergence_lists_name_corpus_files() -> None:
    known = {corpus_id(p) for kind in ("idl4", "invalid") for p in corpus_files(kind)}
    stale = (set(IDL4_REASONS) | set(OMNIIDL_DIVERGENCES)) - known
    assert not stale, f"divergences listed for files that do not exist: {sorted(stale)}"
