"""Decoding of IDL literals: integers, floats, fixed-point, characters and strings."""

from __future__ import annotations

import re
from decimal import Decimal, InvalidOperation

_ESCAPE = re.compile(
    r"\\(?:([ntvbrfa\\?'\"])|([0-7]{1,3})|x([0-9a-fA-F]{1,2})|u([0-9a-fA-F]{1,4})|(.))", re.S
)
_SIMPLE = {
    "n": "\n", "t": "\t", "v": "\v", "b": "\b", "r": "\r", "f": "\f", "a": "\a",
    "\\": "\\", "?": "?", "'": "'", '"': '"',
}  # fmt: skip


class LiteralError(ValueError):
    """A malformed literal; the message is ready for the user."""


MAX_INTEGER_DIGITS = 30  # 2**64 has 20 decimal digits; longer literals are out of range anyway


def decode_integer(text: str) -> int:
    if len(text.lstrip("0")) > MAX_INTEGER_DIGITS:
        raise LiteralError(f"integer literal {shorten(text)} is too large for any IDL integer type")
    if text[:2] in ("0x", "0X"):
        return int(text[2:], 16)
    if len(text) > 1 and text[0] == "0":
        if any(c in "89" for c in text):
            raise LiteralError(f"invalid digit in octal literal '{shorten(text)}'")
        return int(text, 8)
    return int(text)


def shorten(text: str, limit: int = 24) -> str:
    """A literal as quoted in a message: long ones are cut."""
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def decode_float(text: str) -> float:
    value = float(text)
    if value == float("inf"):
        raise LiteralError(f"floating-point literal {shorten(text)} is out of range")
    return value


def decode_fixed(text: str) -> Decimal:
    try:
        value = Decimal(text[:-1] if text[-1] in "dD" else text)
    except InvalidOperation as e:  # pragma: no cover - the lexer only passes valid digits
        raise LiteralError(f"invalid fixed-point literal '{text}'") from e
    return value


def decode_escapes(body: str, wide: bool) -> str:
    """Replace escape sequences in the body of a char or string literal."""
    if "\\" not in body:
        return body

    def repl(m: re.Match[str]) -> str:
        if m.group(1) is not None:
            return _SIMPLE[m.group(1)]
        if m.group(2) is not None:
            code = int(m.group(2), 8)
            if code > 255:
                raise LiteralError(f"octal escape '\\{m.group(2)}' is out of range")
            return chr(code)
        if m.group(3) is not None:
            return chr(int(m.group(3), 16))
        if m.group(4) is not None:
            if not wide:
                raise LiteralError("'\\u' escapes are only allowed in wide literals")
            code = int(m.group(4), 16)
            if 0xD800 <= code <= 0xDFFF:
                raise LiteralError(f"'\\u{m.group(4)}' is a UTF-16 surrogate, not a character")
            return chr(code)
        raise LiteralError(f"unknown escape sequence '\\{m.group(5)}'")

    return _ESCAPE.sub(repl, body)


def decode_char(text: str) -> str:
    """`'a'`, `'\\n'`, `L'x'` -> the character."""
    wide = text[0] == "L"
    body = text[2:-1] if wide else text[1:-1]
    value = decode_escapes(body, wide)
    if len(value) != 1:
        raise LiteralError(f"character literal {text} must hold exactly one character")
    if not wide and ord(value) > 255:
        raise LiteralError(f"character literal {text} is not an ISO Latin-1 character")
    return value


def decode_string(text: str, latin1: bool = True) -> str:
    """One string literal token (`"..."` or `L"..."`) -> its value; `latin1=False` lets
    narrow literals hold any character (DDS and ROS 2 files are UTF-8: rosidl writes
    `@default (value="ハローワールド")` for a wstring)."""
    wide = text[0] == "L"
    body = text[2:-1] if wide else text[1:-1]
    value = decode_escapes(body, wide)
    if "\0" in value:
        raise LiteralError("string literals may not contain a NUL character")
    if latin1 and not wide and any(ord(c) > 255 for c in value):
        raise LiteralError("narrow string literals may only hold ISO Latin-1 characters")
    return value
