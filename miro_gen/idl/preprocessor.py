"""IDL preprocessor: the subset of the C preprocessor that IDL files use.

Handles `#include "x"`/`<x>` (searched in the including file's folder, then the `-I` folders),
`#define`/`#undef` (object-like and function-like macros), `#if/#ifdef/#ifndef/#elif/#else/#endif`
with `defined(...)`, `#pragma once`, `#error`, `#warning` and `#line`. The `prefix`, `version` and
`ID` pragmas are passed on to the parser as normalised `#pragma` lines, because their meaning
depends on IDL scopes; other pragmas are dropped.

Output is line-aligned: every output line comes from exactly one source line, recorded in
`line_map`, so that the parser's positions map back to the original file, line and column.
Comments are left in place for the lexer, which needs doc comments.
"""

from __future__ import annotations

import contextlib
import os
import re

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl.pp_conditions import MAX_CONDITION_DEPTH as MAX_CONDITION_DEPTH
from miro_gen.idl.pp_conditions import ConditionError, ConditionParser
from miro_gen.idl.pp_expand import MAX_EXPANDED_LINE as MAX_EXPANDED_LINE
from miro_gen.idl.pp_expand import MAX_EXPANSION_DEPTH as MAX_EXPANSION_DEPTH
from miro_gen.idl.pp_expand import ExpansionBudgetExceeded, Macro, MacroExpander, words_of
from miro_gen.idl.pp_lexemes import IDENT, comment_segments, strip_comments
from miro_gen.idl.source_text import SourceText as SourceText  # importable from here as before

MAX_INCLUDE_DEPTH = 200
# Inclusions per translation unit (each #include of a guarded file counts). Real trees stay far
# below (TAO's files: at most about 100); include chains without guards double with
# each level and would otherwise run for minutes.
MAX_INCLUSIONS = 10_000

# `__OMNIIDL__` too, with omniidl 4.2's value: ORB IDL trees (Debian's omniORB tree) choose their
# workarounds by it (`typedef Object _Factory;`, `#include <ir.idl>`), and miro-idl reads IDL as
# omniidl does (as clang defines `__GNUC__`). `-U __OMNIIDL__` removes it.
PREDEFINED_MACROS = {"__MIRO_IDL__": "1", "__OMNIIDL__": "0x2630"}

_DIRECTIVE = re.compile(r"\s*#\s*([A-Za-z_]\w*)?\s*(.*)$", re.S)
_PASSED_PRAGMAS = ("prefix", "version", "ID")


class _Cond:
    __slots__ = ("active", "done", "else_seen", "parent_active", "pos")

    def __init__(self, parent_active: bool, active: bool, pos: SourcePos) -> None:
        self.parent_active = parent_active
        self.active = parent_active and active
        self.done = active  # some branch was taken
        self.else_seen = False
        self.pos = pos


class Preprocessor:
    """Preprocesses one IDL file (and its includes) into a `SourceText`."""

    def __init__(
        self,
        include_dirs: list[str] | tuple[str, ...] = (),
        defines: dict[str, str | None] | None = None,
        diagnostics: Diagnostics | None = None,
        once: set[str] | None = None,
    ) -> None:
        """`once`: read every file at most once (the real paths read so far, shared by the
        runs of this preprocessor and updated by them), as ROS 2's guardless `.idl` files need."""
        self.include_dirs = list(include_dirs)
        self.once = once
        self.diag = diagnostics if diagnostics is not None else Diagnostics()
        self._initial_macros = {
            name: Macro(name, None, value) for name, value in PREDEFINED_MACROS.items()
        }
        for name, value in (defines or {}).items():
            if value is None:  # -U NAME
                self._initial_macros.pop(name, None)
            else:
                self._initial_macros[name] = Macro(name, None, value)
        self._file_cache: dict[str, str | None] = {}
        self._realpaths: dict[str, str] = {}

    # -- public -------------------------------------------------------------------------------
    def run(self, path: str) -> SourceText:
        self.macros = dict(self._initial_macros)
        self._out: list[str] = []
        self._map: list[tuple[int, int, int]] = []
        self._paths: list[str] = []
        self._path_index: dict[str, int] = {}
        self._includes: dict[str, list[str]] = {}
        self._col_maps: dict[int, list[tuple[int, int, bool]]] = {}
        self._once: set[str] = self.once if self.once is not None else set()
        self._instances = 0
        self._depth = 0
        self._inclusions = 0
        # The files being included, outermost first: (real path, shown path, macro generation
        # on entry). The generation counts changes to the macro table: a file included again
        # while the table is as it was on its first entry would repeat itself forever.
        self._chain: list[tuple[str, str, int]] = [(os.path.realpath(path), path, 0)]
        self._macro_gen = 0
        self._expander = MacroExpander(self.macros, self.diag)
        text = self._read(path)
        if text is None:
            self.diag.error(None, f"cannot read '{path}'")
        elif self.once is None or os.path.realpath(path) not in self.once:
            # Past the expansion budget (reported), the rest would be expanded wrongly: stop.
            with contextlib.suppress(ExpansionBudgetExceeded):
                self._process(path, text)
        return SourceText(
            "\n".join(self._out) + "\n", self._map, self._paths, self._includes, self._col_maps
        )

    # -- files --------------------------------------------------------------------------------
    def _read(self, path: str) -> str | None:
        if path in self._file_cache:
            return self._file_cache[path]
        try:
            with open(path, "rb") as f:
                data = f.read()
        except OSError:
            self._file_cache[path] = None
            return None
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")  # IDL source is ISO Latin-1 by the standard
        if text.startswith("\ufeff"):
            text = text[1:]
        self._file_cache[path] = text
        return text

    def _path_id(self, path: str) -> int:
        idx = self._path_index.get(path)
        if idx is None:
            idx = len(self._paths)
            self._paths.append(path)
            self._path_index[path] = idx
        return idx

    def _search_dirs(self, current: str, quoted: bool) -> list[str]:
        """Where `#include "x"` (the including file's folder, then the -I folders) or
        `#include <x>` (the -I folders only) looks, as the C preprocessor and omniidl do."""
        return [os.path.dirname(current), *self.include_dirs] if quoted else self.include_dirs

    def _find_include(self, name: str, dirs: list[str]) -> str | None:
        if os.path.isabs(name):
            return name if os.path.isfile(name) else None
        for d in dirs:
            candidate = os.path.normpath(os.path.join(d, name)) if d else os.path.normpath(name)
            if os.path.isfile(candidate):
                return candidate
        return None

    # -- main loop ----------------------------------------------------------------------------
    def _process(self, path: str, text: str) -> None:
        pid = self._path_id(path)
        self._includes.setdefault(path, [])
        self._expander.add_source(len(text))
        if self.once is not None:
            self.once.add(self._realpath(path))
        instance = self._instances
        self._instances += 1
        lines = text.split("\n")
        n = len(lines)
        conds: list[_Cond] = []
        in_comment = False
        comment_start: SourcePos | None = None
        line_offset = 0  # adjusted by #line
        out = self._out
        out_map = self._map
        # The words of the whole file, found in one scan: while no macro is named by any of
        # them (most files, most of the time), no line needs the per-line look for macros.
        # Spliced lines can join words, so a file with backslashes is looked at line by line.
        words = None if "\\" in text else words_of(text)
        words_gen = -1  # the macro table's generation `may_expand` was computed for
        may_expand = True
        i = 0
        while i < n:
            raw = lines[i]
            lineno = i + 1
            first = i
            if raw.endswith("\r"):
                raw = raw[:-1]
            # Splice continuation lines (backslash-newline); they become empty output lines.
            while raw.endswith("\\") and i + 1 < n:
                i += 1
                nxt = lines[i]
                if nxt.endswith("\r"):
                    nxt = nxt[:-1]
                raw = raw[:-1] + nxt
            extra = i - first
            i += 1
            active = not conds or conds[-1].active
            src_line = lineno + line_offset

            if not in_comment and raw.lstrip().startswith("#"):
                pos = SourcePos(path, src_line, raw.index("#") + 1)
                comment_tail = ""
                if "/*" in raw:  # a block comment may start on a directive line
                    _, in_comment, opened = comment_segments(raw, False)
                    if opened is not None:
                        comment_start = SourcePos(path, src_line, opened + 1)
                        comment_tail = " " * opened + raw[opened:]  # the lexer must see '/*'
                emitted = self._directive(raw, pos, path, conds, active)
                if emitted is None:
                    out.append(comment_tail)
                    out_map.append((pid, src_line, instance))
                elif isinstance(emitted, tuple):  # "#line" change
                    new_line, new_path = emitted
                    out.append("")
                    out_map.append((pid, src_line, instance))
                    line_offset = new_line - (lineno + extra) - 1
                    if new_path is not None:
                        pid = self._path_id(new_path)
                        path = new_path
                else:
                    out.append(emitted + comment_tail[len(emitted) :])
                    out_map.append((pid, src_line, instance))
            else:
                start_in_comment = in_comment
                if in_comment or "/*" in raw:
                    _, in_comment, opened = comment_segments(raw, in_comment)
                    if opened is not None:
                        comment_start = SourcePos(path, src_line, opened + 1)
                if active:
                    if words_gen != self._macro_gen:
                        words_gen = self._macro_gen
                        may_expand = words is None or not self.macros.keys().isdisjoint(words)
                    if may_expand and self._expander.uses_macros(raw):
                        raw, cmap = self._expander.expand_line(
                            raw, start_in_comment, SourcePos(path, src_line, 1), self._macro_gen
                        )
                        self._col_maps[len(out)] = cmap
                    out.append(raw)
                else:
                    # Keep comment delimiters balanced for the lexer: an inactive line is blank.
                    out.append("")
                out_map.append((pid, src_line, instance))
            for k in range(extra):
                out.append("")
                out_map.append((pid, src_line + k + 1, instance))
        if in_comment and comment_start is not None:
            self.diag.error(comment_start, "unterminated comment")
        for c in conds:
            self.diag.error(c.pos, "unterminated conditional directive (missing #endif)")

    # -- directives ---------------------------------------------------------------------------
    def _directive(
        self, line: str, pos: SourcePos, path: str, conds: list[_Cond], active: bool
    ) -> str | tuple[int, str | None] | None:
        m = _DIRECTIVE.match(line)
        assert m is not None
        name = m.group(1) or ""
        rest = strip_comments(m.group(2)).strip()

        # Conditionals are interpreted even in inactive regions.
        if name in ("if", "ifdef", "ifndef"):
            if not active:
                conds.append(_Cond(False, False, pos))
                return None
            if name == "if":
                value = self._eval_condition(rest, pos)
            else:
                ident = IDENT.match(rest)
                if not ident:
                    self.diag.error(pos, f"#{name} needs a macro name")
                    value = False
                else:
                    value = (ident.group(0) in self.macros) == (name == "ifdef")
            conds.append(_Cond(True, value, pos))
            return None
        if name == "elif":
            if not conds or conds[-1].else_seen:
                self.diag.error(pos, "#elif without #if" if not conds else "#elif after #else")
                return None
            c = conds[-1]
            if c.parent_active and not c.done:
                value = self._eval_condition(rest, pos)
                c.active = value
                c.done = value
            else:
                c.active = False
            return None
        if name == "else":
            if not conds or conds[-1].else_seen:
                self.diag.error(pos, "#else without #if" if not conds else "#else after #else")
                return None
            c = conds[-1]
            c.else_seen = True
            c.active = c.parent_active and not c.done
            c.done = True
            return None
        if name == "endif":
            if not conds:
                self.diag.error(pos, "#endif without #if")
            else:
                conds.pop()
            return None
        if not active:
            return None

        if name == "":
            if rest and rest[0].isdigit():  # "# 12 "file"" line marker
                return self._line_directive(rest, pos)
            return None
        if name == "include":
            self._include(rest, pos, path)
            return None
        if name == "define":
            self._define(rest, pos)
            return None
        if name == "undef":
            ident = IDENT.match(rest)
            if ident:
                if self.macros.pop(ident.group(0), None) is not None:
                    self._macro_gen += 1
            else:
                self.diag.error(pos, "#undef needs a macro name")
            return None
        if name == "pragma":
            words = rest.split(None, 1)
            if not words:
                return None
            if words[0] == "once":
                self._once.add(os.path.realpath(path))
                return None
            if words[0] in _PASSED_PRAGMAS:
                return "#pragma " + rest
            return None  # other pragmas (omniORB, DDS keylist, ...) do not affect the AST
        if name == "error":
            self.diag.error(pos, f"#error {rest}".rstrip())
            return None
        if name == "warning":
            self.diag.warning(pos, f"#warning {rest}".rstrip())
            return None
        if name == "line":
            return self._line_directive(rest, pos)
        if name in ("ident", "sccs"):
            return None
        self.diag.error(pos, f"unknown preprocessor directive '#{name}'")
        return None

    def _line_directive(self, rest: str, pos: SourcePos) -> tuple[int, str | None] | None:
        m = re.fullmatch(r'([0-9]+)(?:\s+"([^"]*)")?(?:\s+[0-9]+)*\s*', rest)
        if not m or len(m.group(1)) > 10:
            self.diag.error(pos, 'malformed #line directive: expected #line NUMBER ["FILE"]')
            return None
        line = int(m.group(1))
        if line < 1:
            self.diag.error(pos, f"#line number must be positive, not {line}")
            return None
        return line, m.group(2)

    def _include(self, rest: str, pos: SourcePos, current: str) -> None:
        if rest and rest[0] not in '"<' and self.macros:
            rest = self._expander.expand_text(rest, pos, self._macro_gen).strip()
        m = re.match(r'"([^"]+)"|<([^>]+)>', rest)
        if not m:
            self.diag.error(pos, '#include expects "FILE" or <FILE>')
            return
        quoted = m.group(1) is not None
        name = m.group(1) or m.group(2)
        dirs = self._search_dirs(current, quoted)
        found = self._find_include(name, dirs)
        if found is None:
            searched = ", ".join(d or "." for d in dirs) or "no -I folders given"
            hint = ""
            if not quoted and self._find_include(name, self._search_dirs(current, True)):
                hint = f'; it is beside the including file: write #include "{name}" or add -I'
            self.diag.error(pos, f"cannot find include file '{name}' (searched: {searched}{hint})")
            return
        incs = self._includes.setdefault(current, [])
        if found not in incs:
            incs.append(found)
        real = self._realpath(found)
        if real in self._once:
            return
        text = self._read(found)
        if text is None:
            self.diag.error(pos, f"cannot read include file '{found}'")
            return
        if not self._may_include(real, found, pos):
            return
        self._depth += 1
        self._chain.append((real, found, self._macro_gen))
        try:
            self._process(found, text)
        finally:
            self._depth -= 1
            self._chain.pop()

    def _realpath(self, path: str) -> str:
        real = self._realpaths.get(path)
        if real is None:
            real = self._realpaths[path] = os.path.realpath(path)
        return real

    def _may_include(self, real: str, shown: str, pos: SourcePos) -> bool:
        """Report an include cycle that never ends, too deep nesting or too many inclusions."""
        self._inclusions += 1
        if self._inclusions > MAX_INCLUSIONS:
            if self._inclusions == MAX_INCLUSIONS + 1:  # once
                self.diag.error(
                    pos,
                    f"more than {MAX_INCLUSIONS} inclusions: files are included again and "
                    "again; protect them with include guards (#ifndef X_IDL / #define X_IDL / "
                    "... / #endif) or #pragma once",
                )
            return False
        earlier = [i for i, (r, _, _) in enumerate(self._chain) if r == real]
        forever = any(self._chain[i][2] == self._macro_gen for i in earlier)
        if forever or self._depth >= MAX_INCLUDE_DEPTH:
            cycle = ""
            if earlier:
                names = [p for _, p, _ in self._chain[earlier[-1] :]]
                cycle = ": " + " -> ".join([*names, shown])
            what = (
                "#include cycle" + cycle + "; without include guards it never ends "
                "(#ifndef X_IDL / #define X_IDL / ... / #endif, or #pragma once)"
                if forever
                else f"#include nested more than {MAX_INCLUDE_DEPTH} deep{cycle}"
            )
            self.diag.error(pos, what)
            return False
        return True

    def _define(self, rest: str, pos: SourcePos) -> None:
        m = re.match(r"([A-Za-z_]\w*)(\(([^)]*)\))?\s*(.*)$", rest, re.S)
        if not m:
            self.diag.error(pos, "#define needs a macro name")
            return
        name = m.group(1)
        params: tuple[str, ...] | None = None
        if m.group(2) is not None:
            plist = [p.strip() for p in m.group(3).split(",")] if m.group(3).strip() else []
            if any(not IDENT.fullmatch(p) for p in plist):
                self.diag.error(pos, f"malformed parameter list in #define {name}")
                return
            params = tuple(plist)
        macro = Macro(name, params, m.group(4).strip())
        if self.macros.get(name) != macro:
            self.macros[name] = macro
            self._macro_gen += 1

    # -- #if expressions ----------------------------------------------------------------------
    def _eval_condition(self, expr: str, pos: SourcePos) -> bool:
        # Replace defined(X) / defined X before expanding macros.
        def repl(m: re.Match[str]) -> str:
            return "1" if (m.group(1) or m.group(2)) in self.macros else "0"

        expr = re.sub(r"\bdefined\s*(?:\(\s*([A-Za-z_]\w*)\s*\)|([A-Za-z_]\w*))", repl, expr)
        expr = self._expander.expand_text(expr, pos, self._macro_gen)
        try:
            return ConditionParser(expr).parse() != 0
        except ConditionError as e:
            self.diag.error(pos, f"invalid #if expression: {e}")
            return False
