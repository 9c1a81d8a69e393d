"""The IDL test corpus under tests/corpus/ and the expectations written in its files.

Layout:

- `corpus/valid/*.idl`: CORBA 3 IDL that both miro-idl and omniidl accept.
- `corpus/idl4/*.idl`: IDL that miro-idl accepts and omniidl does not (IDL 4 features, CORBA
  constructs omniidl lacks, values omniidl computes wrongly).
- `corpus/invalid/*.idl`: IDL that must be rejected.
- `corpus/include/`: headers the corpus includes; every corpus file is compiled with
  `-I tests/corpus/include`.

Expectations are comments in the IDL files (put at the end so that they do not move the lines
they talk about):

- `// expect: L:C: text`: an error at line L, column C whose message contains `text`.
  An invalid file must produce exactly its expected errors (notes and warnings aside), unless it
  also says `// expect-more` (further errors allowed, e.g. a cascade).
- `// expect-warning: L:C: text`: a warning; valid and idl4 files must produce exactly their
  expected warnings.
- `// check: NAME {json}`: the AST JSON declaration named NAME (the first one with that name,
  or with that name and kind when the fragment gives "kind") contains the JSON fragment: every
  key of an object must be present with a matching value, lists must have the same length and
  match element by element, scalars must be equal and of the same JSON type.

Known bugs of miro-idl are listed in KNOWN_BUGS and mark the affected tests as strict xfails, so
that the suite stays green and an xfail turns into a failure once the bug is fixed.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from miro_gen.diagnostics import CompileError, Diagnostic, Diagnostics
from miro_gen.idl import compile_idl
from miro_gen.idl.ast_json import dumps, specifications_json

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
CORPUS = TESTS / "corpus"
INCLUDE_DIR = CORPUS / "include"

# file (relative to tests/corpus) -> (reason, the tests it breaks)
#   "api":  tests/idl/test_corpus.py through compile_idl (compiles cleanly / expected diagnostics)
#   "cli":  tests/idl/test_corpus.py through `python -m miro_gen.cli.idl` (invalid files)
#   "diff": tests/idl/test_differential_omniidl.py
KNOWN_BUGS: dict[str, tuple[str, frozenset[str]]] = {}


@dataclass(frozen=True)
class Expected:
    line: int
    col: int
    text: str

    def __str__(self) -> str:
        return f"{self.line}:{self.col}: {self.text}"

    def matches(self, line: int, col: int, message: str) -> bool:
        return line == self.line and col == self.col and self.text in message


@dataclass
class Directives:
    errors: list[Expected] = field(default_factory=list)
    more: bool = False
    warnings: list[Expected] = field(default_factory=list)
    checks: list[tuple[str, dict[str, Any]]] = field(default_factory=list)


_EXPECT = re.compile(
    r"//\s*expect(?P<warn>-warning)?:\s*(?P<line>\d+):(?P<col>\d+):\s*(?P<text>.*)$"
)
_MORE = re.compile(r"//\s*expect-more\b")
_CHECK = re.compile(r"//\s*check:\s*(?P<name>\S+)\s+(?P<json>\{.*\})\s*$")


def parse_directives(path: Path) -> Directives:
    out = Directives()
    for lineno, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        line = raw.strip()
        if m := _EXPECT.match(line):
            exp = Expected(int(m["line"]), int(m["col"]), m["text"].rstrip())
            (out.warnings if m["warn"] else out.errors).append(exp)
        elif _MORE.match(line):
            out.more = True
        elif m := _CHECK.match(line):
            try:
                fragment = json.loads(m["json"])
            except json.JSONDecodeError as e:  # a mistake in the corpus itself
                raise ValueError(f"{path}:{lineno}: bad JSON in check: {e}") from e
            out.checks.append((m["name"], fragment))
        elif line.startswith("// expect") or line.startswith("// check"):
            raise ValueError(f"{path}:{lineno}: malformed corpus directive: {line}")
    return out


def corpus_files(kind: str) -> list[Path]:
    return sorted((CORPUS / kind).glob("*.idl"))


def corpus_id(path: Path) -> str:
    """`valid/basic_types.idl`: the key of KNOWN_BUGS and the pytest id."""
    return path.relative_to(CORPUS).as_posix()


def repo_relative(path: Path) -> str:
    """The path as given on the command line (tests run from the repository root)."""
    return path.relative_to(REPO).as_posix()


def params(kind: str, test: str) -> list[Any]:
    """pytest parameters for the corpus files of `kind`, with strict xfails for known bugs."""
    out = []
    for p in corpus_files(kind):
        cid = corpus_id(p)
        marks = []
        bug = KNOWN_BUGS.get(cid)
        if bug is not None and test in bug[1]:
            marks.append(pytest.mark.xfail(strict=True, reason=bug[0]))
        out.append(pytest.param(p, id=cid, marks=marks))
    return out


def fragment_mismatch(fragment: Any, actual: Any, where: str = "") -> str | None:
    """Why `actual` does not contain `fragment` (see the module docstring), or None."""
    if isinstance(fragment, dict):
        if not isinstance(actual, dict):
            return f"{where or 'value'}: expected an object, got {actual!r}"
        for k, v in fragment.items():
            if k not in actual:
                return f"{where}.{k}: missing"
            why = fragment_mismatch(v, actual[k], f"{where}.{k}")
            if why:
                return why
        return None
    if isinstance(fragment, list):
        if not isinstance(actual, list) or len(actual) != len(fragment):
            return f"{where}: expected {len(fragment)} items, got {actual!r}"
        for i, (f, a) in enumerate(zip(fragment, actual, strict=True)):
            why = fragment_mismatch(f, a, f"{where}[{i}]")
            if why:
                return why
        return None
    if type(fragment) is not type(actual) or fragment != actual:
        return f"{where}: expected {fragment!r}, got {actual!r}"
    return None


def find_declaration(decls: list[dict[str, Any]], name: str, kind: str | None) -> dict[str, Any]:
    for d in decls:
        if d["name"] == name and (kind is None or d["kind"] == kind):
            return d
    raise AssertionError(f"no declaration named {name!r}" + (f" of kind {kind}" if kind else ""))


def compile_corpus_file(path: Path) -> tuple[dict[str, Any] | None, list[Diagnostic]]:
    """The AST JSON document (None when rejected) and every diagnostic, as miro-idl gives them."""
    rel = repo_relative(path)
    diag = Diagnostics()
    cwd = os.getcwd()
    os.chdir(REPO)  # paths in diagnostics and JSON as on the command line
    try:
        spec = compile_idl(rel, [repo_relative(INCLUDE_DIR)], {}, diag)
    except CompileError:
        return None, diag.items
    finally:
        os.chdir(cwd)
    return json.loads(dumps(specifications_json([rel], [spec]))), diag.items
