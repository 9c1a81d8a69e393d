"""A generated type described to DDS peers: the cyclonedds classes (`IdlStruct`) of the same
shape, under the DDS names the RMWs use, from which the cyclonedds wheel makes the XTypes type
information it announces (no I/O).

Fast DDS (ROS 2 Kilted's rmw_fastrtps) matches a reader and a writer only when the type
information both announce agrees; a cyclonedds topic cannot be made without any. These classes
are used for that alone: payloads are the generated classes' own CDR (written and taken as
bytes, ros2/endpoints.py), which is faster than the wheel's interpreted serialiser
(bench/bench_ros2.py measures both).
"""

from __future__ import annotations

import functools
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as _t

from miro_gen.ros2 import names, schema

t: Any = _t  # its generic aliases (`sequence[...]`) are not typed as generic

_PRIMITIVES: dict[str, Any] = {
    "boolean": bool,
    "octet": t.byte,
    "char": t.char,
    "int8": t.int8,
    "uint8": t.uint8,
    "short": t.int16,
    "int16": t.int16,
    "unsigned short": t.uint16,
    "uint16": t.uint16,
    "long": t.int32,
    "int32": t.int32,
    "unsigned long": t.uint32,
    "uint32": t.uint32,
    "long long": t.int64,
    "int64": t.int64,
    "unsigned long long": t.uint64,
    "uint64": t.uint64,
    "float": t.float32,
    "double": t.float64,
}


def dds_type_name(scoped: str) -> str:
    """The DDS name of a struct: the RMWs' `pkg::msg::dds_::Name_` for a ROS 2 type (three
    scopes, the middle one `msg`, `srv` or `action`), else its IDL scoped name."""
    parts = scoped.split("::")
    if len(parts) == 3 and parts[1] in ("msg", "srv", "action"):
        return names.type_to_dds("/".join(parts))
    return scoped


@functools.cache
def idl_struct(data_schema: str) -> type[IdlStruct]:
    """The cyclonedds class describing the type whose data schema is `data_schema` (cached:
    a class is made once per schema, as cyclonedds registers every class it makes). Services
    do not go through cyclonedds (ros2/services.py), so no type with rmw_cyclonedds' request
    header is made here."""
    parsed = schema.read(data_schema)
    made: dict[str, type[IdlStruct]] = {}
    top = parsed.top.scoped
    for struct in parsed.structs.values():
        fields = {m.name: _field(m.type, made) for m in struct.members}
        name = dds_type_name(struct.scoped)
        label = name.replace("::", "_")
        made[struct.scoped] = make_idl_struct(label, name, fields)
    return made[top]


def _field(ref: schema.TypeRef, made: dict[str, type[IdlStruct]]) -> Any:
    match ref:
        case schema.Primitive(name) if name in _PRIMITIVES:
            return _PRIMITIVES[name]
        case schema.String(bound, False):
            return str if bound is None else t.bounded_str[bound]
        case schema.Sequence(element, bound):
            inner = _field(element, made)
            return t.sequence[inner] if bound is None else t.sequence[inner, bound]
        case schema.Array(element, dims):
            inner = _field(element, made)
            for d in reversed(dims):
                inner = t.array[inner, d]
            return inner
        case schema.Named(scoped) if scoped in made:
            return made[scoped]
    raise schema.SchemaError(f"{ref} has no DDS type description here (wstring, wchar, ...)")
