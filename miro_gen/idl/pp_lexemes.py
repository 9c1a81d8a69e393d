"""The pieces of a line the preprocessor tells apart: comments (line and block, which may span
lines), string and character literals, identifiers; and splitting a macro call's arguments and
substituting them into its body."""

from __future__ import annotations

import re

IDENT = re.compile(r"[A-Za-z_]\w*")


# Pieces of a line that matter for comment tracking and macro expansion.
LEXEME = re.compile(
    r'"(?:[^"\\\n]|\\.)*"?'  # string literal (possibly unterminated)
    r"|'(?:[^'\\\n]|\\.)*'?"  # char literal
    r"|//|/\*|\*/"
    r"|[A-Za-z_]\w*"
)


def comment_segments(
    line: str, in_comment: bool
) -> tuple[list[tuple[str, bool]], bool, int | None]:
    """Split `line` into (text, is_code) pieces given the block-comment state at its start.

    Returns the pieces, the block-comment state at the end of the line and, when a block comment
    is still open there, the 0-based column where it began on this line (None if it began earlier).
    """
    pieces: list[tuple[str, bool]] = []
    i = 0
    code_start = 0
    opened: int | None = None
    n = len(line)
    while i < n:
        if in_comment:
            end = line.find("*/", i)
            if end < 0:
                pieces.append((line[code_start:], False))
                return pieces, True, opened
            pieces.append((line[code_start : end + 2], False))
            i = code_start = end + 2
            in_comment = False
            opened = None
            continue
        m = LEXEME.search(line, i)
        if m is None:
            break
        tok = m.group(0)
        if tok == "//":
            pieces.append((line[code_start : m.start()], True))
            pieces.append((line[m.start() :], False))
            return pieces, False, None
        if tok == "/*":
            pieces.append((line[code_start : m.start()], True))
            code_start = m.start()
            opened = m.start()
            in_comment = True
            i = m.end()
            continue
        i = m.end()
    # Also reached for an empty line, which leaves a block comment open.
    pieces.append((line[code_start:], not in_comment))
    return pieces, in_comment, opened if in_comment else None


def substitute_params(body: str, args: dict[str, str]) -> str:
    """Replace a function-like macro's parameter names in its body by the (expanded) arguments."""
    return IDENT.sub(lambda m: args.get(m.group(0), m.group(0)), body)


def strip_comments(text: str) -> str:
    """Remove comments from a directive's text (keeping string literals)."""
    out: list[str] = []
    i = 0
    while True:
        m = LEXEME.search(text, i)
        if m is None:
            out.append(text[i:])
            break
        tok = m.group(0)
        if tok == "//":
            out.append(text[i : m.start()])
            break
        if tok == "/*":
            out.append(text[i : m.start()] + " ")
            end = text.find("*/", m.end())
            if end < 0:
                break
            i = end + 2
            continue
        out.append(text[i : m.end()])
        i = m.end()
    return "".join(out)


# What matters inside a macro call's arguments; the rest is skipped in C, not char by char.
_ARG_MARK = re.compile(r"""[(),"']""")


def split_args(text: str, open_paren: int) -> tuple[list[str], int]:
    """Split a macro call's arguments; returns (args, index after ')') or ([], -1)."""
    depth = 0
    args: list[str] = []
    start = open_paren + 1
    find = _ARG_MARK.search
    m = find(text, open_paren)
    while m is not None:
        i = m.start()
        c = text[i]
        if c in "\"'":
            literal = LEXEME.match(text, i)
            m = find(text, literal.end() if literal else i + 1)
            continue
        if c == "(":
            depth += 1
        elif c == ")":
            depth -= 1
            if depth == 0:
                args.append(text[start:i])
                return args, i + 1
        elif depth == 1:  # ','
            args.append(text[start:i])
            start = i + 1
        m = find(text, i + 1)
    return [], -1
