"""Doc comments: `///`, `//!`, `/** */`, `/*! */` before a declaration, or `///<` and `/**<`
after it (Doxygen's forms), cleaned of their markers and attached to the declaration whose name
is nearest (`attach_docs`), after parsing."""

from __future__ import annotations

from bisect import bisect_left
from typing import Any


def _doc_text(comment: str) -> tuple[str, bool] | None:
    """The text of a doc comment and whether it documents the preceding declaration."""
    if comment.startswith("//"):
        if len(comment) < 3 or comment[2] not in "/!" or comment.startswith("////"):
            return None
        body = comment[3:]
        after = body.startswith("<")
        if after:
            body = body[1:]
        return (body[1:] if body.startswith(" ") else body).rstrip(), after
    if len(comment) < 5 or comment[2] not in "*!" or comment.startswith("/**/"):
        return None
    if comment.startswith("/***"):
        return None
    body = comment[3:-2]
    after = body.startswith("<")
    if after:
        body = body[1:]
    lines = body.split("\n")
    cleaned: list[str] = []
    for i, line in enumerate(lines):
        s = line.strip()
        if i > 0 and s.startswith("*"):
            s = s[1:]
            s = s[1:] if s.startswith(" ") else s
        cleaned.append(s.rstrip() if i == 0 else (line if not line.strip().startswith("*") else s))
    # Dedent continuation lines that were not star-prefixed.
    text = "\n".join(x.rstrip() for x in cleaned).strip("\n")
    return _dedent(text), after


def _dedent(text: str) -> str:
    lines = text.split("\n")
    if len(lines) == 1:
        return lines[0].strip()
    first, rest = lines[0].strip(), lines[1:]
    indents = [len(x) - len(x.lstrip()) for x in rest if x.strip()]
    cut = min(indents) if indents else 0
    return "\n".join([first, *(x[cut:] for x in rest)]).strip()


def attach_docs(named: list[tuple[int, Any]], comments: list[tuple[int, str]]) -> None:
    """Give each named node the doc comments between the previous named node and itself."""
    if not comments or not named:
        return
    named.sort(key=lambda item: item[0])
    starts = [n[0] for n in named]
    pending: dict[int, list[tuple[str, bool]]] = {}
    for offset, comment in comments:
        parsed = _doc_text(comment)
        if parsed is None:
            continue
        text, after = parsed
        at = bisect_left(starts, offset)
        idx = at - 1 if after else at
        if 0 <= idx < len(named) and text:
            pending.setdefault(idx, []).append((text, comment.startswith("/*")))
    for idx, texts in pending.items():
        node = named[idx][1]
        if getattr(node, "doc", None) is None:
            node.doc = _join_docs(texts) or None


def _join_docs(texts: list[tuple[str, bool]]) -> str:
    """Consecutive `///` lines form one paragraph; a block comment is a paragraph of its own,
    as Doxygen reads a `//!` brief followed by a `/** */` description."""
    out = ""
    prev_block = False
    for i, (text, block) in enumerate(texts):
        if i:
            out += "\n\n" if block or prev_block else "\n"
        out += text
        prev_block = block
    return out
