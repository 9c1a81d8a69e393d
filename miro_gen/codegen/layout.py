"""Line breaking of generated code: one rule, used by every template through `wrap`.

A bracketed construct (a call, a signature, a tuple) is written on one line when that line is
at most `limit` characters long; otherwise it is exploded as ruff formats it: one item per line,
indented by four, each followed by a comma, the closing bracket on a line of its own (or, with
`hug`, all items together on one indented line, without a trailing comma). An exploded construct
explodes the constructs nested in it too.

Templates build the construct with `bracket(head, items, tail)` and lay it out with
`| wrap(limit)`; the limits are in the templates, where the indentation is known. Text is
returned without its first line's indentation: templates indent the rest with `| indent(n)`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

INDENT = "    "


class Bracket(NamedTuple):
    """`head` + items separated by commas + `tail`, e.g. `f(` a, b `)`.

    `flat_head` and `flat_tail` replace head and tail on one line: a tuple that needs its
    parentheses only when exploded (`return (...)` is `return a, b` on one line). (A named
    tuple: templates make one per call, signature and tuple they lay out.)
    """

    head: str
    items: Sequence[str | Bracket]
    tail: str
    flat_head: str | None = None
    flat_tail: str | None = None
    hug: bool = False

    def flat(self) -> str:
        head = self.head if self.flat_head is None else self.flat_head
        tail = self.tail if self.flat_tail is None else self.flat_tail
        inner = ", ".join(i.flat() if isinstance(i, Bracket) else i for i in self.items)
        return f"{head}{inner}{tail}"

    def exploded(self) -> str:
        items = [i.exploded() if isinstance(i, Bracket) else i for i in self.items]
        if self.hug:
            body = INDENT + ", ".join(items).replace("\n", "\n" + INDENT) + "\n"
        else:
            body = "".join(INDENT + i.replace("\n", "\n" + INDENT) + ",\n" for i in items)
        return f"{self.head}\n{body}{self.tail}"


def bracket(
    head: str,
    items: Sequence[str | Bracket],
    tail: str,
    flat_head: str | None = None,
    flat_tail: str | None = None,
    hug: bool = False,
) -> Bracket:
    return Bracket(head, items, tail, flat_head, flat_tail, hug)


def wrap(construct: Bracket, limit: int, items_limit: int | None = None) -> str:
    """The construct on one line if that line takes at most `limit` characters (or, given
    `items_limit`, if its items joined take at most that many), else exploded."""
    line = construct.flat()
    fits = len(line) <= limit
    if items_limit is not None:
        fits = len(", ".join(str(i) for i in construct.items)) <= items_limit
    return line if fits else construct.exploded()
