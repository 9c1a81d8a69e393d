"""The values rosidl_generator_py's classes (the Python the ROS 2 wheels ship) give a new message,
as JSON: run in the ROS 2 environment of tests/ros2_env.py.

    python py_defaults.py TYPE...

prints {TYPE: [field values...] or null} for each ROS 2 type name (`std_msgs/msg/Header`,
`test_msgs/action/Fibonacci_SendGoal_Request`); null for what is no message class there (the
service and action types themselves). Values are plain: nested messages as lists of their
fields' values, arrays and sequences as lists, `byte` fields (bytes of one) as numbers.
"""

from __future__ import annotations

import functools
import importlib
import json
import pkgutil
import sys
from typing import Any


@functools.cache
def classes(package: str) -> dict[str, Any]:
    """The classes of a package's modules by name (`pkg.srv` exports the services alone; their
    requests, responses and events are in its modules)."""
    out: dict[str, Any] = {}
    parent = importlib.import_module(package)
    for info in pkgutil.iter_modules(parent.__path__):
        module = importlib.import_module(f"{package}.{info.name}")
        out |= {k: v for k, v in vars(module).items() if isinstance(v, type)}
    return out


def message_class(name: str) -> Any:
    package, kind, cls = name.split("/")
    return classes(f"{package}.{kind}").get(cls)


def plain(v: Any) -> Any:
    if hasattr(v, "get_fields_and_field_types"):
        return [plain(getattr(v, f)) for f in v.get_fields_and_field_types()]
    if isinstance(v, bytes) and len(v) == 1:
        return v[0]
    if isinstance(v, bytes | bytearray):
        return list(v)
    if hasattr(v, "tolist"):
        return plain(v.tolist())
    if isinstance(v, list | tuple):
        return [plain(x) for x in v]
    return v


def defaults(name: str) -> Any:
    cls = message_class(name)
    if cls is None or not hasattr(cls, "get_fields_and_field_types"):
        return None
    return plain(cls())


if __name__ == "__main__":
    json.dump({name: defaults(name) for name in sys.argv[1:]}, sys.stdout)
