"""ROS 2 interfaces: `.msg`, `.srv` and `.action` files, and rosidl's `.idl`, as ROS 2 Kilted's
rosidl reads them, into the resolved AST the rest of miro-idl uses (`unit.compile_ros2`), with
the RIHS01 type hash of every struct."""

from __future__ import annotations

import os

# The ROS 2 interface files by their suffix, and the kind each holds. Kept here, apart from
# `unit.py`, so that telling a `.msg` from an OMG `.idl` costs no import of the ROS 2 readers
# (lark, among others): `miro-idl` on OMG IDL never loads them.
INTERFACE_SUFFIXES = {".msg": "msg", ".srv": "srv", ".action": "action"}


def is_interface_file(path: str) -> bool:
    """Whether `path` is a `.msg`, `.srv` or `.action` file (by its name)."""
    return os.path.splitext(path)[1] in INTERFACE_SUFFIXES
