"""Where a key of a TOML file is: the line of `[services.gps]` or of `restart = ...` in it.

`tomllib` reports positions for syntax errors only; a value that parses but makes no sense (a
restart policy that does not exist, a dependency on nothing) must still be reported as
`file:line: error:`. This scanner walks the text line by line, as far as TOML's layout allows
without parsing values: table headers, array-of-table headers and `key = value` lines, skipping
the insides of multi-line strings and arrays. A key it cannot place is given the line of its
nearest enclosing key that it can.
"""

from __future__ import annotations

import re

_BARE = r"[A-Za-z0-9_-]+"
_QUOTED = r'"(?:[^"\\]|\\.)*"|\'[^\']*\''
_KEY = rf"(?:{_BARE}|{_QUOTED})(?:\s*\.\s*(?:{_BARE}|{_QUOTED}))*"
_HEADER = re.compile(rf"^\s*(\[\[?)\s*({_KEY})\s*\]\]?\s*(?:#.*)?$")
_ASSIGN = re.compile(rf"^\s*({_KEY})\s*=")
_PART = re.compile(rf"{_BARE}|{_QUOTED}")


def _parts(key: str) -> tuple[str, ...]:
    out = []
    for m in _PART.finditer(key):
        text = m.group(0)
        if text[0] in "\"'":
            text = text[1:-1]
        out.append(text)
    return tuple(out)


def _opens(line: str) -> tuple[int, str | None]:
    """How many brackets a value line leaves open, and whether it opens a multi-line string
    (the delimiter), ignoring what is inside one-line strings and after a comment."""
    depth, i = 0, 0
    while i < len(line):
        for quote in ('"""', "'''"):
            if line.startswith(quote, i):
                end = line.find(quote, i + 3)
                if end < 0:
                    return depth, quote
                i = end + 3
                break
        else:
            ch = line[i]
            if ch in "\"'":
                end = i + 1
                while end < len(line) and line[end] != ch:
                    end += 2 if ch == '"' and line[end] == "\\" else 1
                i = end + 1
                continue
            if ch == "#":
                break
            if ch in "[{":
                depth += 1
            elif ch in "]}":
                depth -= 1
            i += 1
    return depth, None


class KeyLines:
    """The line (1-based) where each key path of a TOML text is written."""

    def __init__(self, text: str) -> None:
        self.lines: dict[tuple[str, ...], int] = {}
        self.counts: dict[tuple[str, ...], int] = {}  # arrays of tables: elements so far
        table: tuple[str, ...] = ()
        depth, string = 0, None
        for number, line in enumerate(text.splitlines(), 1):
            if string is not None:  # inside a multi-line string
                end = line.find(string)
                if end >= 0:
                    more, string = _opens(line[end + 3 :])
                    depth += more
                continue
            if depth > 0:  # inside a multi-line array or inline table
                more, string = _opens(line)
                depth += more
                continue
            m = _HEADER.match(line)
            if m:
                table = _parts(m.group(2))
                if m.group(1) == "[[":
                    index = self.counts.get(table, 0)
                    self.counts[table] = index + 1
                    self.lines.setdefault(table, number)
                    table = (*table, str(index))
                self.lines.setdefault(table, number)
                continue
            m = _ASSIGN.match(line)
            if m:
                path = (*table, *_parts(m.group(1)))
                for n in range(len(table) + 1, len(path) + 1):
                    self.lines.setdefault(path[:n], number)
                depth, string = _opens(line[m.end() :])

    def line(self, *path: str | int) -> int:
        """The line of `path` (keys, and indexes into arrays of tables), or of the nearest
        enclosing key found; 1 when none is."""
        key = tuple(str(p) for p in path)
        while key:
            if key in self.lines:
                return self.lines[key]
            key = key[:-1]
        return 1
