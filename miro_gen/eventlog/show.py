"""Turning events into text, for `miro log echo`, `miro echo` and `miro log info`."""

from __future__ import annotations

import time

from miro_gen.runtime import registry


def clock_text(ns: int) -> str:
    """Local time of day with microseconds: `08:50:01.123456`."""
    seconds, rest = divmod(ns, 1_000_000_000)
    return time.strftime("%H:%M:%S", time.localtime(seconds)) + f".{rest // 1000:06d}"


def date_text(ns: int) -> str:
    seconds, rest = divmod(ns, 1_000_000_000)
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(seconds)) + f".{rest // 1000:06d}"


def payload_text(type_hash: str, data: bytes) -> str:
    """The decoded payload, or why it cannot be decoded."""
    cls = registry.find(type_hash) if type_hash else None
    if cls is None:
        name = f"type hash {type_hash[:12]}" if type_hash else "no type hash"
        return f"({len(data)} bytes; no generated type here has {name})"
    try:
        return repr(cls.deserialize(data))
    except Exception as e:
        return f"({len(data)} bytes that do not decode as {cls._type_name}: {e})"
