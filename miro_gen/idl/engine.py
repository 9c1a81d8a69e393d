"""A fused scanner and LALR driver for the grammar in `grammar.lark`.

Lark compiles the grammar into an LALR(1) table. `build_tables` turns that into plain data (the
action table, one child-selection recipe per rule, the terminals), which is cached on disk per
user, so a run normally loads a pickle and never imports Lark; Lark runs again only when the
grammar changes. `Engine` binds the recipes to a transformer's methods (the same rule/alias naming
and child filtering as Lark's, including `?rule` pass-through, `[x]` placeholders and `x*` lists)
and runs the table in one tight loop:

* one compiled regular expression scans each token, skipping whitespace and comments in C;
  comments are collected by a separate scan (they carry the doc comments);
* the scan is contextual where it matters: a word that is a keyword becomes the keyword token
  only if the parser can accept that keyword here, otherwise an identifier (so `map`, `int8` or
  `annotation` stay usable as names); `>>` where the parser can close a template argument list
  (`sequence<sequence<long>>`) is split into two `>`, as in C++11;
* tokens no rule keeps (punctuation, anonymous keywords) are pushed as None, and `?rule`s that
  pass a single child through cost no call.

`build_tables` reads Lark's LALR tables through Lark's private structure (the parser's
`parse_table` and `callbacks`, each rule's `expansion` and `options`); Lark offers no public
access to them. tests/idl/test_idl_engine_lark.py pins every attribute read, and checks that the
engine builds the same parse tree as Lark's own parser on the project's IDL and the corpus, so a
Lark release that changes them fails there. Why not Lark's parser: the engine parses about twice
as fast and skips compiling the grammar (`python bench/bench_idl.py` measures it).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import re
import sys
import zlib
from collections.abc import Callable
from operator import itemgetter
from typing import Any

ENGINE_FORMAT = 5  # bump when the table layout below changes
# Parser stack entries allowed: thousands of nesting levels (about 4 entries per module), far
# beyond real IDL; deeper input is reported where it happens instead of exhausting recursion
# in the later passes.
MAX_STACK = 20_000
# Braces, parentheses, square and angle brackets open at once (modules, types, expressions
# together), as clang's -fbracket-depth (256). Refused while scanning, before any node is
# built: the passes after the parser spend time and memory quadratic in the depth of modules
# (5,000 nested modules took 141 s and 889 MB), real IDL nests fewer than ten.
MAX_NESTING = 256
_BRACKETS = {"{": 1, "(": 1, "[": 1, "<": 1, "}": -1, ")": -1, "]": -1, ">": -1}

# Scan order: the regular expression tries its alternatives in turn, so the frequent tokens
# come first where no earlier alternative could take them: identifiers after the wide literals
# (`L"..."`, `L'x'`), punctuation before the number and quote literals (no punctuation starts
# one: a sign is an operator). Among the numbers, the most specific first.
_HEAD_ORDER = ("PRAGMA", "WCHAR", "WSTRING", "IDENT")
_LITERAL_ORDER = ("FIXED", "FLOAT", "INTEGER", "CHAR", "STRING")
_IGNORED = ("WS", "COMMENT")
_LITERALS = ("WSTRING", "WCHAR", "STRING", "CHAR")

Tables = dict[str, Any]
Callback = Callable[[list[Any]], Any]


class Tok(str):
    """A token: its text, with its terminal name and offset in the parsed text."""

    __slots__ = ("start_pos", "type")

    type: str
    start_pos: int


class ParseFailure(Exception):
    """A syntax error at `offset` of the parsed text."""

    def __init__(self, offset: int, message: str) -> None:
        super().__init__(message)
        self.offset = offset
        self.message = message


class GrammarMismatch(Exception):
    """The transformer lacks a callback the grammar needs (a programming error)."""


# ---- building the tables (needs Lark) --------------------------------------------------------


def build_tables(grammar: str) -> Tables:
    """Compile `grammar` with Lark and extract what the engine needs, as plain data."""
    from lark import Lark
    from lark.lexer import PatternStr
    from lark.parsers.lalr_analysis import Shift

    lark = Lark(grammar, parser="lalr", lexer="basic", maybe_placeholders=True)
    lalr = lark.parser.parser.parser  # ParsingFrontend -> LALR_Parser -> _Parser
    table = lalr.parse_table
    rules = list(lalr.callbacks)

    # Lark names are `Token` (str subclasses); keep plain str so loading never imports Lark.
    kept_terms = sorted(
        {str(sym.name) for r in rules for sym in r.expansion if sym.is_term and not sym.filter_out}
    )
    index = {id(rule): i for i, rule in enumerate(rules)}
    recipes = []
    for rule in rules:
        expansion = rule.expansion
        empty = rule.options.empty_indices
        if empty:
            bits = "".join(str(int(b)) for b in empty)
            nones_at = [len(ones) for ones in bits.split("0")]
        else:
            nones_at = [0] * (len(expansion) + 1)
        include = []
        nones = 0
        for i, sym in enumerate(expansion):
            nones += nones_at[i]
            if not (sym.is_term and sym.filter_out):
                expand = not sym.is_term and sym.name.startswith("_")
                include.append((i, expand, nones))
                nones = 0
        trailing = nones + nones_at[len(expansion)]
        recipes.append(
            {
                "size": len(expansion),
                "origin": str(rule.origin.name),
                "name": str(rule.alias or rule.origin.name),
                "include": include,
                "trailing": trailing,
                "expand1": bool(rule.options.expand1 and not rule.alias),
                "helper": rule.origin.name.startswith("__"),
                "left_recursive": bool(expansion) and expansion[0].name == rule.origin.name,
            }
        )
    states: list[dict[str, int]] = [{} for _ in range(max(table.states) + 1)]
    for state, actions in table.states.items():
        row = states[state]
        for sym, (action, arg) in actions.items():
            row[str(sym)] = arg if action is Shift else ~index[id(arg)]

    terminals = {t.name: t for t in lark.terminals}
    keywords: dict[str, str] = {}
    puncts: list[tuple[str, str]] = []
    ident_re = re.compile(terminals["IDENT"].pattern.to_regexp())
    for t in lark.terminals:
        if isinstance(t.pattern, PatternStr):
            value = str(t.pattern.value)
            if ident_re.fullmatch(value):
                keywords[value] = str(t.name)
            else:
                puncts.append((str(t.name), value))
    puncts.sort(key=lambda p: (-len(p[1]), p[1]))

    def rx(name: str) -> str:
        return str(terminals[name].pattern.to_regexp())

    skip = "(?:" + "|".join(rx(n) for n in _IGNORED) + ")*"
    parts = [f"(?P<{n}>{rx(n)})" for n in _HEAD_ORDER]
    parts += [f"(?P<{name}>{re.escape(value)})" for name, value in puncts]
    parts += [f"(?P<{n}>{rx(n)})" for n in _LITERAL_ORDER]
    parts.append(r"(?P<_EOF>\Z)")
    literal = "|".join(rx(n) for n in _LITERALS)
    by_value = {value: name for name, value in puncts}
    strings = {
        str(t.name): str(t.pattern.value)
        for t in lark.terminals
        if isinstance(t.pattern, PatternStr)
    }
    return {
        "format": ENGINE_FORMAT,
        "states": states,
        "start": table.start_states["start"],
        "end": table.end_states["start"],
        "recipes": recipes,
        "kept_terms": kept_terms,
        "keywords": keywords,
        "master": skip + "(?:" + "|".join(parts) + ")",
        "skip": skip,
        "comments": f"(?:{literal})|(?P<COMMENT>{rx('COMMENT')})",
        "shr": by_value.get(">>", ""),
        "gt": by_value.get(">", ""),
        "strings": strings,
    }


def load_tables(grammar_path: str, cache_dir: str | None) -> Tables:
    """The tables for the grammar file, from the per-user cache when it is current."""
    with open(grammar_path, "rb") as f:
        grammar = f.read()
    version = f"{sys.version_info[0]}{sys.version_info[1]}"
    key = f"{zlib.crc32(grammar):08x}{len(grammar):x}-{ENGINE_FORMAT}-{version}"
    path = os.path.join(cache_dir, f"idl-tables-{key}.pickle") if cache_dir else None
    if path is not None:
        try:
            with open(path, "rb") as f:
                tables: Tables = pickle.load(f)
            if tables.get("format") == ENGINE_FORMAT:
                return tables
        except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ValueError):
            pass
    tables = build_tables(grammar.decode("utf-8"))
    if path is not None:
        tmp = f"{path}.{os.getpid()}.tmp"
        try:
            with open(tmp, "wb") as f:
                pickle.dump(tables, f, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(tmp, path)
        except OSError:  # an unwritable cache only costs start-up time
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return tables


# ---- binding callbacks ----------------------------------------------------------------------


class _Rep(list[Any]):
    """The list a repetition rule (`x*`, `x+`) builds; expanded into its parent's children."""

    __slots__ = ()


def _bind(recipe: dict[str, Any], transformer: Any) -> tuple[Callback | None, int]:
    """The callback for one rule, or (None, i) when the rule passes child i through."""
    include: list[tuple[int, bool, int]] = recipe["include"]
    trailing: int = recipe["trailing"]
    if recipe["helper"]:
        return _repetition(include, recipe["left_recursive"]), 0
    plain = trailing == 0 and all(not e and not n for _, e, n in include)
    if recipe["expand1"] and plain and len(include) == 1:
        return None, include[0][0]
    method = getattr(transformer, recipe["name"], None)
    if method is None:
        raise GrammarMismatch(
            f"the transformer has no callback for grammar rule '{recipe['name']}'"
        )
    if recipe["expand1"]:
        filt = _filter(include, trailing)

        def expand_single(children: list[Any]) -> Any:
            kept = filt(children)
            return kept[0] if len(kept) == 1 else method(kept)

        return expand_single, 0
    if plain:
        if len(include) == recipe["size"]:
            return method, 0
        idx = [i for i, _, _ in include]
        if not idx:
            return (lambda children: method([])), 0
        if len(idx) == 1:
            only = idx[0]
            return (lambda children: method([children[only]])), 0
        getter = itemgetter(*idx)
        return (lambda children: method(list(getter(children)))), 0
    filt = _filter(include, trailing)
    return (lambda children: method(filt(children))), 0


def _select(out: list[Any], children: list[Any], include: list[tuple[int, bool, int]]) -> list[Any]:
    """Append the kept `children` to `out`, with None placeholders for absent `[x]`s and the
    items of repetition lists spliced in (Lark's child filtering)."""
    for i, expand, nones in include:
        if nones:
            out.extend([None] * nones)
        if expand:
            out.extend(children[i])
        else:
            out.append(children[i])
    return out


def _filter(include: list[tuple[int, bool, int]], trailing: int) -> Callback:
    def select(children: list[Any]) -> list[Any]:
        out = _select([], children, include)
        if trailing:
            out.extend([None] * trailing)
        return out

    return select


def _repetition(include: list[tuple[int, bool, int]], left_recursive: bool) -> Callback:
    rest = include[1:] if left_recursive else include
    if len(rest) == 1 and not rest[0][1] and not rest[0][2]:  # `x*` of one kept item
        only = rest[0][0]
        if left_recursive:

            def extend(children: list[Any]) -> _Rep:
                out: _Rep = children[0]
                out.append(children[only])
                return out

            return extend
        return lambda children: _Rep((children[only],))

    def build(children: list[Any]) -> _Rep:
        out: _Rep = children[0] if left_recursive else _Rep()
        _select(out, children, rest)
        return out

    return build


# ---- the engine -----------------------------------------------------------------------------


class Engine:
    """Parses text with the grammar's tables, calling `transformer`'s methods for each rule."""

    def __init__(
        self,
        tables: Tables,
        transformer: Any,
        describe: Callable[[str], str],
        unsupported: dict[str, str],
        reserved: frozenset[str] = frozenset(),
    ) -> None:
        self.states: list[dict[str, int]] = tables["states"]
        self.start: int = tables["start"]
        self.end: int = tables["end"]
        self.rules = [(r["size"], r["origin"], *_bind(r, transformer)) for r in tables["recipes"]]
        self.kept_terms = frozenset(tables["kept_terms"])
        self.keywords: dict[str, str] = tables["keywords"]
        self.master = re.compile(tables["master"])
        self.skip = re.compile(tables["skip"])
        self.comment_scan = re.compile(tables["comments"])
        self.shr: str = tables["shr"]
        self.gt: str = tables["gt"]
        self.strings: dict[str, str] = tables["strings"]
        # terminal -> +1 (opens a bracket) or -1 (closes one)
        self.brackets = {t: _BRACKETS[v] for t, v in self.strings.items() if v in _BRACKETS}
        self.describe = describe
        self.unsupported = unsupported
        self.reserved = reserved  # words that are keywords in every context

    def parse(self, text: str, comments: list[tuple[int, str]]) -> Any:
        """Parse `text`; its comments are appended to `comments` as (offset, text)."""
        for cm in self.comment_scan.finditer(text):
            if cm.lastgroup == "COMMENT":
                comments.append((cm.start(), cm.group()))
        states = self.states
        rules = self.rules
        keywords = self.keywords
        reserved = self.reserved
        kept = self.kept_terms
        match = self.master.match
        shr, gt = self.shr, self.gt
        brackets = self.brackets
        nesting = 0
        end_state = self.end
        state = self.start
        state_stack = [state]
        value_stack: list[Any] = []
        pos = 0
        tok: Any
        after_at = False  # annotation names may be keywords: @default, @oneway
        while True:
            # ---- scan one token ----------------------------------------------------------
            m = match(text, pos)
            if m is None:
                raise self._bad_char(text, self.skip.match(text, pos).end())  # type: ignore[union-attr]
            kind: str = m.lastgroup  # type: ignore[assignment]
            start, pos = m.span(kind)  # the token ends the match: skipped text comes first
            if kind == "_EOF":
                kind = "$END"
                tok = None
            else:
                if kind == "IDENT":
                    word = text[start:pos]
                    kw = keywords.get(word)
                    # After '@', reserved words are annotation names (`@default`, `@oneway`).
                    if kw is not None and not (after_at and word in reserved):
                        actions = states[state]
                        if kw in actions:
                            # LALR rows merge contexts: when both could follow, ask for real.
                            if (
                                word in reserved
                                or "IDENT" not in actions
                                or self._accepts(state_stack, kw)
                            ):
                                kind = kw
                        elif word not in reserved:
                            if "IDENT" not in actions:
                                kind = kw  # neither fits: report the keyword
                        elif not self._keyword_as_name(text, pos, state_stack):
                            kind = kw  # reserved: a syntax error that names it
                elif (
                    kind == shr
                    and gt in states[state]
                    and self._accepts(state_stack, gt)  # `>>` closing two template lists
                ):
                    pos = start + 1
                    kind = gt
                if kind in brackets:
                    nesting += brackets[kind]
                    if nesting > MAX_NESTING:
                        raise ParseFailure(
                            start,
                            f"'{text[start]}' nested more than {MAX_NESTING} deep (braces, "
                            "parentheses and brackets together); miro-idl stops here",
                        )
                after_at = kind == "AT"
                if kind in kept:
                    tok = Tok(text[start:pos])
                    tok.type = kind
                    tok.start_pos = start
                else:
                    tok = None
            # ---- feed it ---------------------------------------------------------------
            while True:
                act = states[state].get(kind)
                if act is None:
                    raise self._unexpected(kind, text, start, state_stack)
                if act >= 0:
                    state = act
                    state_stack.append(act)
                    value_stack.append(tok)
                    if len(state_stack) > MAX_STACK:
                        raise ParseFailure(start, "declarations or expressions nested too deeply")
                    break
                size, origin, cb, pick = rules[~act]
                if cb is None:  # a rule that passes one child through (`?rule`)
                    if size == 1:  # the value stays where it is: only the state changes
                        state = states[state_stack[-2]][origin]
                        state_stack[-1] = state
                        continue
                    value = value_stack[pick - size]
                    del value_stack[-size:]
                    del state_stack[-size:]
                elif size:
                    value = cb(value_stack[-size:])
                    del value_stack[-size:]
                    del state_stack[-size:]
                else:
                    value = cb([])
                state = states[state_stack[-1]][origin]
                state_stack.append(state)
                value_stack.append(value)
                if state == end_state and kind == "$END":
                    return value

    def _keyword_as_name(self, text: str, end: int, state_stack: list[int]) -> bool:
        """Whether a misplaced reserved word ending at `end` reads as a name (`long in;`), so
        that it is scanned as an identifier, reported by the transformer, and parsing goes on;
        followed by a name (`module M {` inside an interface) it is a misplaced declaration."""
        nxt = self.master.match(text, end)
        if nxt is not None and nxt.lastgroup == "IDENT":
            return False
        return "IDENT" in self.states[state_stack[-1]] and self._accepts(state_stack, "IDENT")

    def _accepts(self, state_stack: list[int], kind: str) -> bool:
        """Whether `kind` would be shifted after the reductions it triggers (no side effects)."""
        states = self.states
        stack = list(state_stack)
        while True:
            act = states[stack[-1]].get(kind)
            if act is None:
                return False
            if act >= 0:
                return True
            size, origin, _, _ = self.rules[~act]
            if size:
                del stack[-size:]
            stack.append(states[stack[-1]][origin])

    # ---- syntax errors --------------------------------------------------------------------
    def _expected(self, state_stack: list[int]) -> list[str]:
        """What could really come next (LALR rows list more: their lookaheads merge contexts)."""
        row = self.states[state_stack[-1]]
        return sorted(
            {
                self.describe(s)
                for s in row
                if (s.isupper() or s == "$END") and self._accepts(state_stack, s)
            }
        )

    def _unexpected(self, kind: str, text: str, start: int, state_stack: list[int]) -> ParseFailure:
        expected = self._expected(state_stack)
        if kind == "$END":
            what = "end of file"
            if len(expected) > 8:
                for closing in ("'}'", "';'", "')'", "'>'"):
                    if closing in expected:
                        return ParseFailure(start, f"unexpected end of file; expected {closing}")
        else:
            m = self.master.match(text, start)
            value = text[m.start(m.lastgroup) : m.end()] if m and m.lastgroup else text[start]
            what = f"'{value}'"
            if value in self.keywords:
                what = f"keyword '{value}'"
                if value == "void":
                    return ParseFailure(start, "'void' can only be the return type of an operation")
                # `module M {` where no module may be: a misplaced declaration; `long module;`:
                # a keyword meant as a name. The next token tells them apart.
                nxt = self.master.match(text, start + len(value))
                named = nxt is not None and nxt.lastgroup == "IDENT"
                if value in _DECLARATION_KEYWORDS and (named or "identifier" not in expected):
                    article = "an" if value[0] in "aeiou" else "a"
                    return ParseFailure(start, f"{article} {value} declaration is not allowed here")
                if value in self.reserved and "identifier" in expected:
                    return ParseFailure(
                        start,
                        f"'{value}' is a keyword and cannot be used as a name here "
                        f"(write '_{value}' to use it as an identifier)",
                    )
            if kind == "IDENT" and value in self.unsupported:
                return ParseFailure(
                    start, f"{self.unsupported[value]} are not supported by miro-idl"
                )
        if len(expected) <= 8:
            return ParseFailure(start, f"unexpected {what}; expected {_join(expected)}")
        return ParseFailure(start, f"unexpected {what}")

    def _bad_char(self, text: str, pos: int) -> ParseFailure:
        ch = text[pos]
        if ch == "#":
            msg = "preprocessor directive or #pragma is not allowed here"
        elif ch == '"' or text.startswith('L"', pos):
            msg = "unterminated or malformed string literal"
        elif ch == "'" or text.startswith("L'", pos):
            msg = "malformed character literal"
        elif text.startswith("/*", pos):
            msg = "unterminated comment"
        else:
            msg = f"unexpected character {ch!r}"
        return ParseFailure(pos, msg)


_DECLARATION_KEYWORDS = frozenset(
    ["module", "interface", "valuetype", "exception", "typedef", "const", "native"]
)


def _join(items: list[str]) -> str:
    if len(items) == 1:
        return items[0]
    return ", ".join(items[:-1]) + " or " + items[-1]
