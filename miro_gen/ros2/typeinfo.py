"""Topics announced without XTypes type information, as rmw_cyclonedds announces its own.

Fast DDS (ROS 2 Kilted's rmw_fastrtps) matches a reader and a writer that both announce type
information only when their type identifiers are equal, and it describes ROS 2 collections
with element flags that Cyclone DDS refuses as invalid (so Cyclone cannot even make a type of
the same identifier): a cyclonedds endpoint announcing type information never matches a Fast
DDS one of a type holding a sequence or an array. Without type information both match by type
name, which is how rmw_cyclonedds and rmw_fastrtps nodes talk to each other.

The cyclonedds Python binding needs the type information to make a topic (it checks samples
against it), and announces it. So once a topic is made, the type information its sertype
holds is hidden from the endpoints made on it: the sertype's sizes of its serialized type
information and type map are set to zero. The layout of the binding's sertype is not public:
the fields are found by looking, in the sertype's memory, for the pointer and size of the very
bytes the binding was given, and nothing is changed unless both are found.
"""

from __future__ import annotations

import ctypes as ct
import functools
from typing import Any

from cyclonedds.internal import load_cyclonedds

_SCAN_BYTES = 512  # how far into the sertype to look


class TypeInformationError(RuntimeError):
    """The binding's sertype is not laid out as expected (another cyclonedds version)."""


@functools.cache
def _get_sertype() -> Any:
    fn = load_cyclonedds().dds_get_entity_sertype
    fn.restype = ct.c_int32
    fn.argtypes = [ct.c_int32, ct.POINTER(ct.c_void_p)]
    return fn


def hide(topic: Any) -> None:
    """Stop the endpoints made on `topic` (a cyclonedds Topic) from announcing its type
    information."""
    info, tmap = topic.data_type.__idl__._xt_bytedata
    sertype = ct.c_void_p()
    if _get_sertype()(topic._ref, ct.byref(sertype)) < 0 or not sertype.value:
        raise TypeInformationError("cyclonedds gave no sertype for the topic")
    base = sertype.value
    found = [_field(base, info), _field(base, tmap)]
    if None in found:
        raise TypeInformationError(
            "cannot find the type information in this cyclonedds version's sertype"
        )
    for offset in found:
        assert offset is not None
        ct.c_uint32.from_address(base + offset).value = 0


def _field(base: int, blob: bytes) -> int | None:
    """The offset of the size field that follows a pointer to a copy of `blob`."""
    step = ct.sizeof(ct.c_void_p)
    for off in range(0, _SCAN_BYTES, step):
        ptr = ct.c_void_p.from_address(base + off).value
        size = ct.c_uint32.from_address(base + off + step).value
        if ptr and size == len(blob) and ct.string_at(ptr, size) == blob:
            return off + step
    return None
