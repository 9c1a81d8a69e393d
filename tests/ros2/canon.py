"""One comparable form of a ROS 2 message's value, the same in the ROS 2 environment (rclpy's
classes) and in miro-gen's (generated classes): nested dicts of the fields, numbers, text, and
long sequences as their length and digest. Standard library only: both environments import it.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

LONG = 32


def pattern(n: int) -> bytes:
    """The bytes a `{"__pattern__": n}` value stands for (large payloads in small specs)."""
    return bytes((i * 7 + 3) % 256 for i in range(n))


def expand(spec: Any) -> Any:
    if isinstance(spec, dict):
        if set(spec) == {"__pattern__"}:
            return pattern(int(spec["__pattern__"]))
        return {k: expand(v) for k, v in spec.items()}
    if isinstance(spec, list):
        return [expand(v) for v in spec]
    return spec


def canon(value: Any) -> Any:
    if isinstance(value, bytes | bytearray | memoryview):
        value = list(bytes(value))
    if isinstance(value, dict):
        return {k: canon(v) for k, v in sorted(value.items())}
    if hasattr(value, "get_fields_and_field_types"):  # an rclpy message
        return {k: canon(getattr(value, k)) for k in sorted(value.get_fields_and_field_types())}
    if hasattr(value, "__dataclass_fields__"):  # a generated class
        return {k: canon(getattr(value, k)) for k in sorted(value.__dataclass_fields__)}
    if isinstance(value, str | bool | int | float) or value is None:
        return value
    items = [canon(v) for v in value]  # lists, tuples, array.array, numpy arrays
    items = [int(v) if hasattr(v, "item") and isinstance(v.item(), int) else v for v in items]
    if len(items) > LONG:
        text = json.dumps(items, sort_keys=True)
        return {"len": len(items), "sha256": hashlib.sha256(text.encode()).hexdigest()}
    return items
