"""Values in ROS 2 interface files: defaults and constants as rosidl_adapter reads them, and
the value each has once rosidl_adapter has written it into its `.idl` and an IDL parser has
read it back (so that a `.msg` and its `.idl` give the same AST).

rosidl_adapter (Kilted, `parser.py` and `msg/__init__.py`): booleans are `true`/`false`/`1`/
`0`; integers are decimal or Python-prefixed (`0x10`) and range-checked; strings may be quoted
with `"` or `'` (inner quotes escaped); array values are `[a, b]`. In the `.idl`, strings go
through `unicode_escape` (escapes in the text take effect, other bytes stay), and array values
become a string holding the Python `repr` of a tuple.
"""

from __future__ import annotations

import math
import re

from miro_gen.idl.literals import LiteralError, decode_escapes
from miro_gen.idl.rosidl.msg_parser import MsgType

ValueType = bool | int | float | str
_INT_RANGES = {
    f"{sign}int{bits}": (0, 2**bits - 1) if sign else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    for sign in ("", "u")
    for bits in (8, 16, 32, 64)
}


class ValueProblem(ValueError):
    """A value rosidl_adapter rejects; the message is ready for the user."""


def parse_value(t: MsgType, text: str) -> ValueType | list[ValueType]:
    """A default or constant value of type `t` (a primitive, or an array of primitives)."""
    if t.array is None:
        return parse_primitive(t, text)
    if not (text.startswith("[") and text.endswith("]")):
        raise ValueProblem(f"array value '{text}' must start with '[' and end with ']'")
    inner = text[1:-1]
    if t.base in ("string", "wstring"):
        items = _string_items(inner)
    else:
        items = inner.split(",") if inner else []
    if t.array == "fixed" and len(items) != t.size:
        raise ValueProblem(f"array value must have exactly {t.size} elements, not {len(items)}")
    if t.array == "bounded" and t.size is not None and len(items) > t.size:
        raise ValueProblem(f"array value must have at most {t.size} elements, not {len(items)}")
    element = MsgType(t.base, None, t.string_bound)
    return [parse_primitive(element, item.strip()) for item in items]


def parse_primitive(t: MsgType, text: str) -> ValueType:
    base = t.base
    if base == "bool":
        if text.lower() not in ("true", "1", "false", "0"):
            raise ValueProblem(f"boolean value '{text}' must be true, false, 1 or 0")
        return text.lower() in ("true", "1")
    if base in ("byte", "char") or base in _INT_RANGES:
        low, high = _INT_RANGES.get(base, (0, 255))
        try:
            value = int(text)
        except ValueError:
            try:
                value = int(text, 0)
            except ValueError:
                raise ValueProblem(f"'{text}' is not an integer") from None
        if not low <= value <= high:
            raise ValueProblem(f"{base} value {value} is outside {low} .. {high}")
        return value
    if base in ("float32", "float64"):
        try:
            number = float(text)
        except ValueError:
            raise ValueProblem(f"'{text}' is not a floating-point number") from None
        if not math.isfinite(number):
            raise ValueProblem(f"'{text}' is not finite: rosidl_adapter cannot write it as IDL")
        return number
    return _string(t, text)


def _string(t: MsgType, text: str) -> str:
    for quote in ('"', "'"):
        if len(text) >= 2 and text.startswith(quote) and text.endswith(quote):
            text = text[1:-1]
            if re.search(r"(?<!\\)" + quote, text):
                raise ValueProblem(f"string value has an unescaped {quote} inside its quotes")
            text = text.replace("\\" + quote, quote)
            break
    if t.string_bound is not None and len(text) > t.string_bound:
        raise ValueProblem(f"string value is longer than its bound {t.string_bound}")
    return text


def _string_items(text: str) -> list[str]:
    """The elements of a string array value, quoted or not (rosidl_adapter's
    `parse_string_array_value_string`)."""
    items: list[str] = []
    while text:
        text = text.lstrip(" ")
        if not text:
            break
        if text[0] == ",":
            raise ValueProblem(f"unexpected ',' at the start of [{text}]")
        if text[0] in "\"'":
            quote = text[0]
            end = _closing_quote(text, quote)
            if end < 0:
                raise ValueProblem(f"string [{text}] is not closed by {quote}")
            items.append(text[1 : end + 1].replace("\\" + quote, quote))
            text = text[end + 2 :]
        else:
            comma = text.find(",")
            items.append(text if comma < 0 else text[:comma])
            text = "" if comma < 0 else text[comma:]
        text = text.lstrip(" ")
        if text[:1] == ",":
            text = text[1:]
    return items


def _closing_quote(text: str, quote: str) -> int:
    """rosidl_adapter's `find_matching_end_quote`: the index (counted after the opening quote)
    of the quote that closes `text`, or -1."""
    offset = 0
    while text:
        end = text[1:].find(quote)
        if end < 0:
            return -1
        if text[end : end + 2] != "\\" + quote:
            return offset + end
        text = text[end + 2 :]
        offset = end + 2
    return -1


def idl_string(text: str) -> str:
    """The value of the string literal rosidl_adapter writes for `text` in its `.idl`, as an IDL
    parser reads it back (the `.idl` is written in ISO Latin-1 and read as UTF-8)."""
    try:
        escaped = text.encode("utf-8").decode("unicode_escape")
        raw = escaped.encode("latin-1")
    except (UnicodeDecodeError, UnicodeEncodeError) as e:
        raise ValueProblem(f"rosidl_adapter cannot write '{text}' into IDL: {e.reason}") from None
    try:
        body = raw.decode("utf-8")
    except UnicodeDecodeError:
        body = escaped
    try:
        return decode_escapes(body.replace('"', '\\"'), wide=False)
    except LiteralError as e:
        raise ValueProblem(str(e)) from None


def idl_value(t: MsgType, value: ValueType | list[ValueType]) -> ValueType:
    """The value rosidl_adapter's `.idl` gives `@default` or a constant: arrays as the text of a
    Python tuple, strings through `idl_string`, the rest as they are."""
    if isinstance(value, list):
        return repr(tuple(value))
    if isinstance(value, str):
        return idl_string(value)
    return value
