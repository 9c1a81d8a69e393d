"""`#if` and `#elif` expressions, evaluated as C evaluates them once macros are expanded:
integer and character literals, the C operators with their precedence, `?:`; identifiers that
are left (not macros) are 0."""

from __future__ import annotations

import re

from miro_gen.idl.literals import LiteralError, decode_char, decode_integer

MAX_CONDITION_DEPTH = 2_000


class ConditionError(Exception):
    pass


_COND_TOKEN = re.compile(
    r"\s*(?:(0[xX][0-9a-fA-F]+|\d+)[uUlL]*|('(?:[^'\\]|\\.)*')|([A-Za-z_]\w*)"
    r"|(\|\||&&|==|!=|<=|>=|<<|>>|[-+*/%()<>!~&|^?:]))"
)


_BINARY_PREC = {
    "||": 1, "&&": 2, "|": 3, "^": 4, "&": 5, "==": 6, "!=": 6,
    "<": 7, ">": 7, "<=": 7, ">=": 7, "<<": 8, ">>": 8, "+": 9, "-": 9, "*": 10, "/": 10, "%": 10,
}  # fmt: skip


class ConditionParser:
    """Evaluates a preprocessor `#if` expression (after macro expansion) as C does."""

    def __init__(self, text: str) -> None:
        self.tokens: list[tuple[str, object]] = []
        i = 0
        text = text.rstrip()
        while i < len(text):
            m = _COND_TOKEN.match(text, i)
            if not m or m.end() == i:
                raise ConditionError(f"unexpected '{text[i:].strip()[:20]}'")
            if m.group(1) is not None:
                try:
                    value = decode_integer(m.group(1))
                except (LiteralError, ValueError) as e:
                    raise ConditionError(str(e)) from None
                self.tokens.append(("num", value))
            elif m.group(2) is not None:
                try:
                    value = ord(decode_char(m.group(2)))
                except LiteralError as e:
                    raise ConditionError(str(e)) from None
                self.tokens.append(("num", value))
            elif m.group(3) is not None:
                self.tokens.append(("num", 1 if m.group(3) == "true" else 0))
            else:
                self.tokens.append(("op", m.group(4)))
            i = m.end()
        self.i = 0
        self.depth = 0

    def parse(self) -> int:
        if not self.tokens:
            raise ConditionError("empty expression")
        v = self._ternary()
        if self.i != len(self.tokens):
            raise ConditionError(f"unexpected '{self.tokens[self.i][1]}'")
        return v

    def _peek(self) -> str | None:
        if self.i < len(self.tokens) and self.tokens[self.i][0] == "op":
            return str(self.tokens[self.i][1])
        return None

    def _ternary(self) -> int:
        cond = self._binary(1)
        if self._peek() == "?":
            self.i += 1
            a = self._ternary()
            if self._peek() != ":":
                raise ConditionError("expected ':'")
            self.i += 1
            b = self._ternary()
            return a if cond else b
        return cond

    def _binary(self, min_prec: int) -> int:
        left = self._unary()
        while True:
            op = self._peek()
            prec = _BINARY_PREC.get(op or "")
            if op is None or prec is None or prec < min_prec:
                return left
            self.i += 1
            right = self._binary(prec + 1)
            left = _apply(op, left, right)

    def _unary(self) -> int:
        if self.i >= len(self.tokens):
            raise ConditionError("unexpected end of expression")
        kind, value = self.tokens[self.i]
        self.i += 1
        if kind == "num":
            assert isinstance(value, int)
            return value
        if value in ("(", "!", "-", "+", "~"):
            self.depth += 1
            if self.depth > MAX_CONDITION_DEPTH:
                raise ConditionError("expression nested too deeply")
        if value == "(":
            v = self._ternary()
            if self._peek() != ")":
                raise ConditionError("expected ')'")
            self.i += 1
            return v
        if value == "!":
            return int(not self._unary())
        if value == "-":
            return -self._unary()
        if value == "+":
            return self._unary()
        if value == "~":
            return ~self._unary()
        raise ConditionError(f"unexpected '{value}'")


def _apply(op: str, a: int, b: int) -> int:
    if op in ("/", "%"):
        if b == 0:
            raise ConditionError("division by zero")
        q = abs(a) // abs(b) * (1 if (a >= 0) == (b >= 0) else -1)
        return q if op == "/" else a - q * b
    if op in ("<<", ">>") and not 0 <= b < 64:
        raise ConditionError("shift count out of range")
    result: int = {
        "||": lambda: int(bool(a) or bool(b)), "&&": lambda: int(bool(a) and bool(b)),
        "|": lambda: a | b, "^": lambda: a ^ b, "&": lambda: a & b,
        "==": lambda: int(a == b), "!=": lambda: int(a != b), "<": lambda: int(a < b),
        ">": lambda: int(a > b), "<=": lambda: int(a <= b), ">=": lambda: int(a >= b),
        "<<": lambda: a << b, ">>": lambda: a >> b, "+": lambda: a + b, "-": lambda: a - b,
        "*": lambda: a * b,
    }[op]()  # fmt: skip
    return result
