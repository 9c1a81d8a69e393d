"""How deep brackets nest in a piece of C++ (a type, a `default=`, a `<constructor>` block),
checked before Lark parses it.

Lark's LALR parser does not recurse, but the tree it builds is as deep as the text nests, and
the passes over that tree do: 5,000 nested braces took seconds before the recursion limit ended
them with an error at the block, not at the bracket. A scan is linear and cheap. The limit is
Python's own (its parser refuses more than 200 nested parentheses, and constructor code becomes
Python), far beyond anything makeParams files hold.
"""

from __future__ import annotations

import re

MAX_NESTING = 200

# Opening and closing brackets of code: `<`/`>` are brackets in types only (in code they compare).
CODE_BRACKETS = "()[]{}"
TYPE_BRACKETS = "()<>"


def too_deep(text: str, brackets: str = CODE_BRACKETS) -> tuple[int, int] | None:
    """(line, column), 1-based, of the first bracket of `text` that opens more than MAX_NESTING
    at once; None when none does. `brackets` lists pairs, opening first."""
    opening = brackets[0::2]
    depth = 0
    for m in re.finditer("[" + re.escape(brackets) + "]", text):
        if m.group() in opening:
            depth += 1
            if depth > MAX_NESTING:
                start = m.start()
                line_start = text.rfind("\n", 0, start) + 1
                return text.count("\n", 0, start) + 1, start - line_start + 1
        elif depth > 0:
            depth -= 1
    return None
