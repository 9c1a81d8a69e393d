"""The IDL parser's engine reads Lark's LALR tables through Lark's private structure
(miro_gen/idl/engine.py, `build_tables`); this test pins what it reads, so that a Lark upgrade
that moves or changes it fails here, by name, instead of misparsing silently.

Why not Lark's own parser: it parses about 2.3 times slower and compiles the grammar on every
run (0.25 s). Why not the standalone parser Lark's generator writes: it is Lark's parser too
(about 2.2 times slower) in 3,600 generated lines to keep in the repository. `python
bench/bench_idl.py` measures all three on the same text and checks they build the same tree.

Two checks: every private attribute `build_tables` uses exists with the meaning it assumes, and
the engine, run on tables built from the installed Lark, parses the project's IDL, the corpus
and a large generated file into exactly the tree Lark's own LALR parser builds.
"""

from __future__ import annotations

import sys
from functools import cache
from pathlib import Path
from typing import Any

import lark
import pytest
from lark import Lark, Tree
from lark.grammar import Rule
from lark.lexer import PatternStr, TerminalDef
from lark.parsers.lalr_analysis import Reduce, Shift
from repo_paths import REPO

from miro_gen.diagnostics import Diagnostics
from miro_gen.idl import engine
from miro_gen.idl.parser import GRAMMAR_PATH
from miro_gen.idl.preprocessor import Preprocessor

sys.path.insert(0, str(REPO / "bench"))
from gen_idl import module


@cache
def lark_parser() -> Lark:
    return Lark(
        GRAMMAR_PATH.read_text(), parser="lalr", lexer="contextual", maybe_placeholders=True
    )


@cache
def tables() -> engine.Tables:
    return engine.build_tables(GRAMMAR_PATH.read_text())  # from the installed Lark, not a cache


def test_the_private_structure_build_tables_reads() -> None:
    """`Lark.parser.parser.parser` is the LALR `_Parser`: its `parse_table` has `states`
    (state -> {symbol name: (Shift, state) or (Reduce, Rule)}), `start_states` and `end_states`
    by start symbol, and its `callbacks` are keyed by every `Rule`, whose `expansion` symbols
    have `name`, `is_term`, `filter_out`, whose `origin` has `name`, and whose `options` have
    `empty_indices` (one flag per position: a `[x]` placeholder left out) and `expand1`."""
    built = Lark(GRAMMAR_PATH.read_text(), parser="lalr", lexer="basic", maybe_placeholders=True)
    lalr = built.parser.parser.parser
    table = lalr.parse_table
    assert isinstance(table.states, dict) and table.states
    assert set(table.start_states) == {"start"} and set(table.end_states) == {"start"}
    actions = {action for row in table.states.values() for action, _ in row.values()}
    assert actions == {Shift, Reduce}, actions
    for row in table.states.values():
        for name, (action, arg) in row.items():
            assert isinstance(name, str)
            assert isinstance(arg, int if action is Shift else Rule), (name, action, arg)
    rules = list(lalr.callbacks)
    assert rules and all(isinstance(r, Rule) for r in rules)
    reduced = {id(arg) for row in table.states.values() for a, arg in row.values() if a is Reduce}
    assert reduced <= {id(r) for r in rules}, "reductions name rules the callbacks do not have"
    for r in rules:
        assert isinstance(r.origin.name, str)
        assert r.alias is None or isinstance(r.alias, str)
        for sym in r.expansion:
            assert isinstance(sym.name, str) and isinstance(sym.is_term, bool)
            assert not sym.is_term or isinstance(sym.filter_out, bool)
        empty = r.options.empty_indices
        assert empty == () or (len(empty) == len(r.expansion) + sum(empty)), (r, empty)
        assert isinstance(r.options.expand1, bool)
    assert all(isinstance(t, TerminalDef) for t in built.terminals)
    strings = [t for t in built.terminals if isinstance(t.pattern, PatternStr)]
    assert strings and all(isinstance(t.pattern.value, str) for t in strings)
    assert all(isinstance(t.pattern.to_regexp(), str) for t in built.terminals)


def test_the_tables_are_what_the_engine_expects() -> None:
    t = tables()
    assert t["format"] == engine.ENGINE_FORMAT
    assert t["states"][t["start"]] and t["end"] != t["start"]
    assert "module" in t["keywords"] and "IDENT" in t["kept_terms"]


class _TreeBuilder:
    """A transformer for the engine that builds Lark's parse tree (rule or alias name and the
    kept children, as Lark's own parser builds it)."""

    def __getattr__(self, rule: str) -> Any:
        return lambda children: Tree(rule, list(children))


def _inputs() -> list[Path]:
    files = sorted((REPO / "idl").glob("*.idl"))
    for folder in ("valid", "idl4"):
        files += sorted((REPO / "tests" / "corpus" / folder).glob("*.idl"))
    return files


def _same_tree(text: str) -> None:
    ours = engine.Engine(tables(), _TreeBuilder(), str, {}).parse(text, [])
    theirs = lark_parser().parse(text)
    assert ours == theirs
    assert _token_types(ours) == _token_types(theirs)


def _token_types(tree: Any) -> list[str]:
    """Tokens compare as strings; their terminal names must agree too."""
    if isinstance(tree, Tree):
        return [t for c in tree.children for t in _token_types(c)]
    return [tree.type] if isinstance(tree, str) else []


@pytest.mark.parametrize("path", _inputs(), ids=lambda p: str(p.relative_to(REPO)))
def test_the_engine_parses_as_lark_does(path: Path) -> None:
    includes = [str(REPO / "idl"), str(REPO / "tests" / "corpus" / "include")]
    text = Preprocessor(includes, {}, Diagnostics()).run(str(path)).text
    try:
        lark_parser().parse(text)
    except lark.exceptions.UnexpectedInput:
        pytest.skip("Lark's contextual lexer cannot scan this file (the engine's scanner can)")
    _same_tree(text)


def test_the_engine_parses_a_large_file_as_lark_does() -> None:
    _same_tree("".join(module(i) for i in range(20)))
