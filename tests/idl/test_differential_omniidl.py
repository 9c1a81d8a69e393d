"""miro-idl against omniidl, Debian's CORBA IDL front end, on the corpus in tests/corpus/.

tests/omniidl_dump.py runs omniidl's own front end (omnicpp + `_omniidl.compile`) under the system
Python that omniidl is built for, and prints each file's declarations in miro-idl's `--ast-json`
shape. It runs once for the whole corpus (module-level cache).

- valid/: both accept, with the same declarations, compared as tests/idl_differential.py
  describes (kinds, scoped names, repository ids, files and order, every per-kind field; not
  doc comments, annotations or getraises/setraises, which omniidl lacks; a declaration's line
  may be earlier than omniidl's, which is the line where its parser finished the head).
- idl4/: miro-idl accepts these and omniidl must reject them; IDL4_REASONS says why for each
  (an IDL 4 feature, a CORBA 3 construct omniidl lacks, or a value omniidl gets wrong).
- invalid/: omniidl must reject them too, with an error on every line where the file expects
  one, except for the documented OMNIIDL_DIVERGENCES (where miro-idl is stricter or omniidl is
  wrong).

Skipped, with the reason, when /usr/bin/python3 (or $MIRO_OMNIIDL_PYTHON) cannot import omniidl's
front end.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import pytest
from idl_corpus import (
    INCLUDE_DIR,
    REPO,
    compile_corpus_file,
    corpus_files,
    corpus_id,
    params,
    parse_directives,
    repo_relative,
)
from idl_differential import declaration_problems, errors_text, omniidl_unavailable
from idl_differential import omniidl_results as run_omniidl

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


SKIP_REASON = omniidl_unavailable()
needs_omniidl = pytest.mark.skipif(SKIP_REASON is not None, reason=SKIP_REASON or "")


@cache
def omniidl_results() -> dict[str, dict[str, Any]]:
    """omniidl's verdict on every corpus file, keyed by corpus id (one run for the corpus)."""
    files = [p for kind in ("valid", "idl4", "invalid") for p in corpus_files(kind)]
    raw = run_omniidl([repo_relative(p) for p in files], [repo_relative(INCLUDE_DIR)], cwd=REPO)
    return {corpus_id(p): raw[repo_relative(p)] for p in files}


def _omniidl(path: Path) -> dict[str, Any]:
    return omniidl_results()[corpus_id(path)]


# ---- the tests ----------------------------------------------------------------------------


@needs_omniidl
@pytest.mark.parametrize("path", params("valid", "diff"))
def test_valid_matches_omniidl(path: Path) -> None:
    omni = _omniidl(path)
    assert omni["ok"], "omniidl rejects a valid/ corpus file:\n" + errors_text(omni)
    doc, items = compile_corpus_file(path)
    assert doc is not None, "miro-idl rejects it:\n" + "\n".join(str(d) for d in items)
    problems = declaration_problems(doc["declarations"], omni["declarations"])
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
            + errors_text(omni)
        )
        return
    assert not omni["ok"], "omniidl accepts this invalid/ file"
    expected_lines = {e.line for e in parse_directives(path).errors}
    flagged = {e["line"] for e in omni["errors"] if e["file"] == path.name}
    unflagged = expected_lines - flagged
    documented = divergence.unflagged if divergence is not None else frozenset()
    assert unflagged == documented, (
        f"lines with an expected error where omniidl reports none: {sorted(unflagged)}"
        f" (documented: {sorted(documented)})\nomniidl said:\n" + errors_text(omni)
    )


def test_divergence_lists_name_corpus_files() -> None:
    known = {corpus_id(p) for kind in ("idl4", "invalid") for p in corpus_files(kind)}
    stale = (set(IDL4_REASONS) | set(OMNIIDL_DIVERGENCES)) - known
    assert not stale, f"divergences listed for files that do not exist: {sorted(stale)}"
