"""The preprocessed text of one translation unit and the map back to its sources: every
output line comes from one source line (`line_map`), with the columns macro expansion moved
(`col_maps`), so that the parser's offsets become file, line and column (`pos_at`)."""

from __future__ import annotations

from bisect import bisect_right

from miro_gen.diagnostics import SourcePos

# SourcePos(path, line, col) without the named tuple's own __new__, a Python function: a fifth
# of the time of `pos_at`, which runs for every name the parser meets.
_new_pos = tuple.__new__


class SourceText:
    """Preprocessed text of one translation unit and the map back to the sources."""

    __slots__ = ("_starts", "col_maps", "includes", "line_map", "paths", "text")

    def __init__(
        self,
        text: str,
        line_map: list[tuple[int, int, int]],
        paths: list[str],
        includes: dict[str, list[str]] | None = None,
        col_maps: dict[int, list[tuple[int, int, bool]]] | None = None,
    ) -> None:
        self.text = text
        # For output line i (0-based): (index into `paths`, source line, file instance id).
        self.line_map = line_map
        self.paths = paths
        # Direct includes of each file (display paths), in order of first inclusion.
        self.includes: dict[str, list[str]] = includes if includes is not None else {}
        # For lines changed by macro expansion (by 0-based output line): column pieces
        # (output column, source column, verbatim), 0-based, sorted by output column.
        self.col_maps: dict[int, list[tuple[int, int, bool]]] = col_maps or {}
        self._starts: list[int] | None = None

    def pos(self, line: int, col: int) -> SourcePos:
        """Source position of 1-based output `line` and `col`."""
        if 1 <= line <= len(self.line_map):
            p, src_line, _ = self.line_map[line - 1]
            cmap = self.col_maps.get(line - 1) if self.col_maps else None
            if cmap:
                i = bisect_right(cmap, (col - 1, 1 << 62, True)) - 1
                if i >= 0:
                    out_col, src_col, verbatim = cmap[i]
                    col = src_col + (col - 1 - out_col if verbatim else 0) + 1
            return SourcePos(self.paths[p], src_line, col)
        # Past the end (EOF errors): last line of the main file.
        if self.line_map:
            p, src_line, _ = self.line_map[-1]
            return SourcePos(self.paths[p], src_line, col)
        return SourcePos(self.paths[0] if self.paths else "<input>", 1, col)

    def pos_at(self, offset: int) -> SourcePos:
        """Source position of character `offset` of `text` (called for every declaration and
        name the parser builds: the common case, a line macros left alone, is inlined)."""
        starts = self._starts
        if starts is None:
            starts = self._line_starts()
        line = bisect_right(starts, offset)
        if line <= len(self.line_map) and (line - 1) not in self.col_maps:
            p, src_line, _ = self.line_map[line - 1]
            return _new_pos(SourcePos, (self.paths[p], src_line, offset - starts[line - 1] + 1))
        return self.pos(line, offset - starts[line - 1] + 1)

    def instance_at(self, offset: int) -> int:
        """File-instance id of the line holding character `offset` of `text`."""
        return self.instance(bisect_right(self._line_starts(), offset))

    def _line_starts(self) -> list[int]:
        starts = self._starts
        if starts is None:
            starts = [0]
            find = self.text.find
            i = find("\n")
            while i >= 0:
                starts.append(i + 1)
                i = find("\n", i + 1)
            self._starts = starts
        return starts

    def instance(self, line: int) -> int:
        """File-instance id of 1-based output `line` (each inclusion of a file is an instance)."""
        if 1 <= line <= len(self.line_map):
            return self.line_map[line - 1][2]
        return 0
