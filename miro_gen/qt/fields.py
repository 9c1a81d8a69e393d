"""Fields of generated IDL values by path, for the widgets that show them (no Qt here).

A path names a field inside a payload as in Python, `data.a`, `points[3].x`, or with `__`
between the parts and plain numbers for indices, as Designer object names must be spelt
(`data__a`, `points__3__x`).
"""

from __future__ import annotations

import dataclasses
import enum
import math
import re
from array import array
from collections.abc import Iterator
from typing import Any

MAX_ITEMS = 16  # elements of a sequence listed, at most; the rest is summarised
_INDEXED = (list, tuple, bytes, array)  # sequences (numbers are array.array) and octets
_PART = re.compile(r"[A-Za-z_][A-Za-z0-9_]*|\d+")


class FieldError(LookupError):
    """A path that names no field of the value."""


def parse_path(path: str) -> list[str | int]:
    """`data.a`, `points[3].x`, `points__3__x` -> ['points', 3, 'x']; ValueError if malformed."""
    text = path.replace("[", ".").replace("]", "").replace("__", ".")
    parts: list[str | int] = []
    for part in text.split(".") if text else []:
        if not _PART.fullmatch(part):
            raise ValueError(f"{path!r} is not a field path (such as data.a or points[3].x)")
        parts.append(int(part) if part.isdigit() else part)
    return parts


def format_path(parts: list[str | int]) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def get_field(value: Any, path: str | list[str | int]) -> Any:
    """The field of `value` at `path`; FieldError naming what is there instead."""
    parts = parse_path(path) if isinstance(path, str) else path
    for i, part in enumerate(parts):
        where = format_path(parts[:i]) or type(value).__name__
        if isinstance(part, int):
            if not isinstance(value, _INDEXED) or part >= len(value):
                size = len(value) if isinstance(value, _INDEXED) else "no"
                raise FieldError(f"{where} has {size} elements, no [{part}]")
            value = value[part]
        else:
            names = field_names(value)
            if part not in names:
                have = ", ".join(names) if names else "no fields"
                raise FieldError(f"{where} has no field {part!r} ({have})")
            value = getattr(value, part)
    return value


def field_names(value: Any) -> list[str]:
    """The fields of a struct (dataclass) or exception, in IDL order; [] for anything else."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return [f.name for f in dataclasses.fields(value)]
    slots = getattr(type(value), "__slots__", None)
    if isinstance(slots, tuple) and hasattr(type(value), "_type_hash"):
        return [s for s in slots if not s.startswith("_")]
    return []


def is_number(value: Any) -> bool:
    """A plottable scalar: int or float (booleans and enums count as their numbers)."""
    return isinstance(value, int | float) and not (isinstance(value, float) and math.isnan(value))


def leaves(value: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(path, value) for every scalar inside `value`, in order; long sequences are cut at
    MAX_ITEMS with a ('path', '... N more') row."""
    names = field_names(value)
    if names:
        for name in names:
            yield from leaves(getattr(value, name), f"{prefix}.{name}" if prefix else name)
    elif isinstance(value, list | tuple | array):
        for i, item in enumerate(value[:MAX_ITEMS]):
            yield from leaves(item, f"{prefix}[{i}]")
        if len(value) > MAX_ITEMS:
            yield f"{prefix}[{MAX_ITEMS}:]", f"... {len(value) - MAX_ITEMS} more"
    else:
        yield prefix or "value", value


def show(value: Any) -> str:
    """A scalar as text: numbers as %g does, enums by name, bytes by size."""
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, bytes):
        return f"{len(value)} bytes"
    return str(value)
