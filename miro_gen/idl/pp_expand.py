"""Macro expansion for the IDL preprocessor, within a budget per translation unit.

The rules are those the preprocessor has always applied: a macro is not expanded again inside
its own expansion (the names being expanded are hidden), a function-like macro's arguments are
expanded before they are substituted (only the arguments its body uses, as cpp does: an unused
argument is never expanded), and the result is scanned again.

Expansion can grow exponentially: `#define A1 A0 A0`, `#define A2 A1 A1`, ... twenty lines make a
megabyte, thirty a gigabyte, and cpp expands whatever it is given (gcc's cpp takes 2 s and 230 MB
for twenty such lines, minutes and gigabytes for a 2 KB file using them). Here:

* the expansion of each fragment is remembered while the macro table stays the same, so a macro
  met again costs a copy of its text, not a second expansion: the work follows the size of the
  output, never the number of paths through the macros;
* one line expands to at most `MAX_EXPANDED_LINE` characters (an error at the macro's use; the
  line is left as written);
* a translation unit has a budget of work: characters scanned or produced by expansion at any
  level, where each macro invocation counts `INVOCATION_COST`. It is `EXPANSION_BUDGET` plus
  `EXPANSION_PER_SOURCE_CHAR` per character of the files read, so that expansion never
  multiplies a small file into a large one (the parser then spends seconds per megabyte) and a
  large file that uses macros throughout still fits. Past it the error names the macro used on
  the line and preprocessing stops (`ExpansionBudgetExceeded`). Real IDL stays far below it: the
  project's files, the corpus and omniORB's IDL tree use at most 2,300 (of a million).
"""

from __future__ import annotations

import re
from functools import lru_cache
from typing import NamedTuple

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl.pp_lexemes import IDENT, LEXEME, comment_segments, split_args, substitute_params

MAX_EXPANSION_DEPTH = 200
MAX_EXPANDED_LINE = 1_000_000
# Characters scanned or produced by macro expansion in one translation unit, at every level of
# nesting (a macro expanding to 1 KB inside one expanding to 10 KB counts 11 KB); one invocation
# counts INVOCATION_COST. The budget: EXPANSION_BUDGET + EXPANSION_PER_SOURCE_CHAR * characters
# of the files read.
EXPANSION_BUDGET = 1_000_000
EXPANSION_PER_SOURCE_CHAR = 16
INVOCATION_COST = 64


# A word as a macro name is found: not the tail of a number or of another word (`1.5d`, `0xFF`).
_WORD = re.compile(r"\b[A-Za-z_]\w*")


def words_of(text: str) -> frozenset[str]:
    """The words of `text` (identifiers, keywords): what could name a macro."""
    return frozenset(_WORD.findall(text))


class Macro(NamedTuple):
    name: str
    params: tuple[str, ...] | None  # None for object-like macros
    body: str


class ExpansionError(Exception):
    """Macro expansion that would not end or would not fit on one line; `macro` and `offset`
    name the invocation on the line being expanded (filled in on the way out)."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message
        self.macro: str | None = None
        self.offset = 0


class ExpansionBudgetExceeded(Exception):
    """The translation unit's expansion budget is spent (already reported): stop preprocessing."""


class _OverBudget(ExpansionError):
    pass


@lru_cache(maxsize=4096)
def _names_in(body: str) -> frozenset[str]:
    """The identifiers of a macro body: which parameters it uses."""
    return frozenset(IDENT.findall(body))


class MacroExpander:
    """Expands the macros of one translation unit's table (shared with the preprocessor, which
    defines and undefines them and says when the table changed by its `generation`)."""

    def __init__(self, macros: dict[str, Macro], diag: Diagnostics) -> None:
        self.macros = macros
        self.diag = diag
        self.work_left = EXPANSION_BUDGET
        self._memo: dict[tuple[str, frozenset[str]], str] = {}
        self._generation = -1

    def add_source(self, chars: int) -> None:
        """A file of `chars` characters was read: the budget grows with the source."""
        self.work_left += EXPANSION_PER_SOURCE_CHAR * chars

    def uses_macros(self, line: str) -> bool:
        """Whether a word of `line` names a macro (the cheap test before expanding it). A set
        lookup per word: a pattern of all macro names, rebuilt after each `#define`, made
        files that define and use macros in turn quadratic (5,000 of each: over a minute)."""
        return not self.macros.keys().isdisjoint(_WORD.findall(line))

    def expand_line(
        self, line: str, in_comment: bool, pos: SourcePos, generation: int
    ) -> tuple[str, list[tuple[int, int, bool]]]:
        """Expand macros in the code parts of `line` (not in comments or literals).

        Also returns the line's column map: (output column, source column, verbatim) pieces,
        so that positions in expanded text point back into the original line. `pos` is the
        line's start; errors are reported at the column of the macro used there.
        """
        self._check_generation(generation)
        segments, _, _ = comment_segments(line, in_comment)
        out: list[str] = []
        cmap: list[tuple[int, int, bool]] = []
        out_len = src_off = 0
        for text, code in segments:
            if code:
                pieces: list[tuple[int, int, bool]] = []
                try:
                    expanded = self._expand(text, pos, frozenset(), pieces, 0)
                except ExpansionError as e:
                    self._report(e, SourcePos(pos.path, pos.line, src_off + e.offset + 1))
                    expanded, pieces = text, [(0, 0, True)]
                cmap.extend((out_len + o, src_off + src, v) for o, src, v in pieces)
            else:
                expanded = text
                cmap.append((out_len, src_off, True))
            out.append(expanded)
            out_len += len(expanded)
            src_off += len(text)
        return "".join(out), cmap

    def expand_text(self, text: str, pos: SourcePos, generation: int) -> str:
        """Expand macros in a directive's text (`#if`, `#include`), reported at `pos`."""
        self._check_generation(generation)
        try:
            return self._expand(text, pos, frozenset(), [], 0)
        except ExpansionError as e:
            self._report(e, pos)
            return text

    # -- inside -------------------------------------------------------------------------------
    def _check_generation(self, generation: int) -> None:
        if generation != self._generation:
            self._memo.clear()
            self._generation = generation

    def _report(self, e: ExpansionError, pos: SourcePos) -> None:
        name = e.macro or "?"
        if isinstance(e, _OverBudget):
            self.diag.error(
                pos,
                f"expanding macro '{name}' goes over the budget for macro expansion in one file "
                f"({EXPANSION_BUDGET:,} characters plus {EXPANSION_PER_SOURCE_CHAR} per "
                "character read); stopping here",
            )
            raise ExpansionBudgetExceeded
        self.diag.error(pos, e.message.format(macro=name))

    def _charge(self, work: int) -> None:
        self.work_left -= work
        if self.work_left < 0:
            raise _OverBudget("")

    def _expand(
        self,
        text: str,
        pos: SourcePos,
        hide: frozenset[str],
        pieces: list[tuple[int, int, bool]] | None,
        depth: int,
    ) -> str:
        """Expand macros in a code fragment without comments; string literals are kept.

        `pieces` (the line's own level only) receives (output offset, source offset, verbatim)
        for each piece of output: verbatim text, or the expansion of the macro invoked there.
        Inner levels (`pieces` None) are remembered by (text, hidden names).
        """
        key = (text, hide)
        if pieces is None:
            done = self._memo.get(key)
            if done is not None:
                self._charge(INVOCATION_COST + len(done))
                return done
        if depth > MAX_EXPANSION_DEPTH:
            raise ExpansionError(
                f"macro '{{macro}}' expands macros nested more than {MAX_EXPANSION_DEPTH} deep"
            )
        self._charge(INVOCATION_COST + len(text))
        errors_before = len(self.diag.items)
        out: list[str] = []
        out_len = 0
        macros = self.macros

        def emit(piece: str, src: int, verbatim: bool) -> None:
            nonlocal out_len
            if not piece:
                return
            if pieces is not None:
                pieces.append((out_len, src, verbatim))
            out.append(piece)
            out_len += len(piece)
            self._charge(len(piece))
            if out_len > MAX_EXPANDED_LINE:
                raise ExpansionError("macro '{macro}' expands to more than 1 MB on one line")

        i = verbatim_from = 0
        n = len(text)
        used_at: tuple[str, int] | None = None  # the macro last met, for errors
        try:
            while True:
                m = LEXEME.search(text, i)
                if m is None:
                    break
                tok = m.group(0)
                i = m.end()
                macro = macros.get(tok)
                if macro is None or tok in hide or not (tok[0].isalpha() or tok[0] == "_"):
                    continue
                used_at = (tok, m.start())
                if macro.params is None:
                    end = i
                    expansion = self._expand(macro.body, pos, hide | {tok}, None, depth + 1)
                else:
                    # Function-like: needs "(" args ")" on the same line; otherwise not a call.
                    j = i
                    while j < n and text[j] in " \t":
                        j += 1
                    if j >= n or text[j] != "(":
                        continue
                    args, end = split_args(text, j)
                    self._charge((end if end >= 0 else n) - j)
                    if end < 0:
                        self.diag.error(pos, f"unterminated argument list for macro '{tok}'")
                        break
                    params = macro.params
                    if len(args) != len(params) and not (not params and args == [""]):
                        self.diag.error(
                            pos,
                            f"macro '{tok}' expects {len(params)} arguments, got {len(args)}",
                        )
                        i = end
                        continue
                    used = _names_in(macro.body)
                    expanded_args = {
                        p: self._expand(a.strip(), pos, hide, None, depth + 1)
                        for p, a in zip(params, args, strict=False)
                        if p in used
                    }
                    body = substitute_params(macro.body, expanded_args)
                    expansion = self._expand(body, pos, hide | {tok}, None, depth + 1)
                emit(text[verbatim_from : m.start()], verbatim_from, True)
                emit(expansion, m.start(), False)
                verbatim_from = i = end
            emit(text[verbatim_from:], verbatim_from, True)
        except ExpansionError as e:
            # Each level names its own use; the line's level (the last to see it) wins.
            if used_at is not None:
                e.macro, e.offset = used_at
            raise
        result = "".join(out)
        if pieces is None and len(self.diag.items) == errors_before:
            self._memo[key] = result  # remembered only when it reported nothing
        return result
