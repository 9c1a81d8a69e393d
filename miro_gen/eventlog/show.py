"""Turning events into text, for `miro log echo`, `miro echo` and `miro log info`; and long
sequences and byte strings abridged for them and `miro call` (an image is 921,600 bytes): their
length and first elements, as `ros2 topic echo --truncate-length` does."""

from __future__ import annotations

import array
import dataclasses
import time
from collections.abc import Callable
from typing import Any

TRUNCATE = 10  # elements of a sequence or byte string shown, by default, before it is abridged


def clock_text(ns: int) -> str:
    """Local time of day with microseconds: `08:50:01.123456`."""
    seconds, rest = divmod(ns, 1_000_000_000)
    return time.strftime("%H:%M:%S", time.localtime(seconds)) + f".{rest // 1000:06d}"


def date_text(ns: int) -> str:
    seconds, rest = divmod(ns, 1_000_000_000)
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(seconds)) + f".{rest // 1000:06d}"


def payload_text(
    type_hash: str, data: bytes, limit: int | None = None, cls: type[Any] | None = None
) -> str:
    """The decoded payload (as `cls`, else the generated type of its hash), long sequences
    abridged past `limit` elements (None: whole), or why it cannot be decoded."""
    from miro_gen.runtime import registry  # here: `miro log info` shows dates, no payload

    if cls is None and type_hash:
        cls = registry.find(type_hash)
    if cls is None:
        name = f"type hash {type_hash[:12]}" if type_hash else "no type hash"
        return f"({len(data)} bytes; no generated type here has {name})"
    try:
        value = cls.deserialize(data)
    except Exception as e:
        return f"({len(data)} bytes that do not decode as {cls._type_name}: {e})"
    return repr(value) if limit is None else abridged(value, limit)


def summary(value: Any, limit: int, show: Callable[[Any], str]) -> str | None:
    """`<921600 bytes: ff d8 ff ...>` or `<1081 items: 0.5, 0.25, ...>` (elements as `show`
    gives them) for a byte string or sequence of more than `limit` elements; None otherwise."""
    if isinstance(value, bytes | bytearray) and len(value) > limit:
        head = " ".join(f"{b:02x}" for b in value[:limit])
        return f"<{len(value)} bytes: {head} ...>"
    if isinstance(value, list | tuple | array.array) and len(value) > limit:
        head = ", ".join(show(v) for v in value[:limit])
        return f"<{len(value)} items: {head}, ...>"
    return None


def abridged(value: Any, limit: int) -> str:
    """`repr(value)`, with every sequence or byte string of more than `limit` elements in it
    abridged to its length and first elements."""
    from miro_gen.runtime.cdr import IdlUnion

    def show(v: Any) -> str:
        short = summary(v, limit, show)
        if short is not None:
            return short
        if isinstance(v, IdlUnion):
            return v._repr_with(show)
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            fields = (
                f"{f.name}={show(getattr(v, f.name))}" for f in dataclasses.fields(v) if f.repr
            )
            return f"{type(v).__qualname__}({', '.join(fields)})"
        if isinstance(v, list):
            return f"[{', '.join(show(x) for x in v)}]"
        return repr(v)

    return show(value)
