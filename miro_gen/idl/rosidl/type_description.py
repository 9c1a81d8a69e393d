"""RIHS01 type hashes of ROS 2 types, from their resolved structs.

rosidl_generator_type_description (Kilted; REP 2011) describes a type by its name
(`pkg/msg/Name`) and its fields, each with a type id (`type_description_interfaces/FieldType`:
the element kind, plus 48 for an array, 96 for a bounded and 144 for an unbounded sequence), a
capacity (array size or sequence bound), a string capacity (a bounded string's bound) and the name
of a nested type; a type's full description is its own and those of every type it refers to,
sorted by name. The hash is SHA-256 over that description as JSON (default values left out,
`", "` and `": "` separators, ASCII), written `RIHS01_<hex>`. Peers put it in discovery data
(the DDS RMWs) and in key expressions (rmw_zenoh).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from miro_gen.idl import ast

RIHS01_PREFIX = "RIHS01_"
_ELEMENT_IDS = {
    "nested": 1, "int8": 2, "uint8": 3, "short": 4, "unsigned short": 5, "long": 6,
    "unsigned long": 7, "long long": 8, "unsigned long long": 9, "float": 10, "double": 11,
    "long double": 12, "char": 13, "wchar": 14, "boolean": 15, "octet": 16, "string": 17,
    "wstring": 18, "bounded string": 21, "bounded wstring": 22,
}  # fmt: skip
_CONTAINER_OFFSETS = {None: 0, "array": 48, "bounded": 96, "unbounded": 144}

Description = dict[str, Any]


class NotDescribable(Exception):
    """A struct ROS 2's type descriptions cannot express (an enum, a union, nested arrays)."""


def type_name(struct: ast.Struct) -> str:
    """The ROS 2 name of a type: `std_msgs/msg/Header` for `std_msgs::msg::Header`."""
    return "/".join(struct.scope_path)


def type_hash(description: Description) -> str:
    """The RIHS01 hash of a full type description (`full_description`)."""
    text = json.dumps(description, ensure_ascii=True, separators=(", ", ": "), allow_nan=False)
    return RIHS01_PREFIX + hashlib.sha256(text.encode("utf-8")).hexdigest()


class TypeDescriptions:
    """The type descriptions of structs, each made once."""

    def __init__(self) -> None:
        self._individual: dict[int, tuple[Description, list[ast.Struct]]] = {}

    def full_description(self, struct: ast.Struct) -> Description:
        """The struct's own description and those of the types it refers to, sorted by name."""
        own, _ = self.individual(struct)
        referenced: dict[str, Description] = {}
        todo = list(self.individual(struct)[1])
        while todo:
            s = todo.pop()
            name = type_name(s)
            if name not in referenced:
                desc, nested = self.individual(s)
                referenced[name] = desc
                todo += nested
        return {
            "type_description": own,
            "referenced_type_descriptions": [referenced[k] for k in sorted(referenced)],
        }

    def individual(self, struct: ast.Struct) -> tuple[Description, list[ast.Struct]]:
        """The struct's own description (no default values) and the structs its fields name."""
        known = self._individual.get(id(struct))
        if known is not None:
            return known
        fields = []
        nested: list[ast.Struct] = []
        for m in struct.all_members:
            try:
                field, inner = _field_type(m.type, m.dims)
            except NotDescribable as e:
                raise NotDescribable(f"member '{m.name}': {e}") from None
            fields.append({"name": m.name, "type": field})
            if inner is not None:
                nested.append(inner)
        result = ({"type_name": type_name(struct), "fields": fields}, nested)
        self._individual[id(struct)] = result
        return result


def _field_type(
    t: ast.TypeSpec | ast.Decl, dims: list[int]
) -> tuple[Description, ast.Struct | None]:
    container: str | None = None
    capacity = 0
    if dims:
        if len(dims) > 1:
            raise NotDescribable("multi-dimensional arrays have no ROS 2 type")
        container, capacity = "array", dims[0]
    else:
        t = _unaliased(t)
        if isinstance(t, ast.Typedef):
            return _field_type(t.type, t.dims)
        if isinstance(t, ast.SequenceType):
            container = "bounded" if t.bound is not None else "unbounded"
            capacity = t.bound or 0
            t = t.element
    element = _unaliased(t)
    if isinstance(element, ast.Typedef):
        raise NotDescribable("arrays or sequences of arrays have no ROS 2 type")
    kind, string_capacity, nested = _element(element)
    field = {
        "type_id": _ELEMENT_IDS[kind] + _CONTAINER_OFFSETS[container],
        "capacity": capacity,
        "string_capacity": string_capacity,
        "nested_type_name": type_name(nested) if nested is not None else "",
    }
    return field, nested


def _unaliased(t: ast.TypeSpec | ast.Decl) -> ast.TypeSpec | ast.Decl:
    """Follow names and typedefs without dimensions to the type they stand for."""
    while True:
        if isinstance(t, ast.NamedType):
            assert t.decl is not None, "unresolved name"
            t = t.decl.resolved
        elif isinstance(t, ast.Typedef) and not t.dims:
            t = t.type
        else:
            return t


def _element(t: ast.TypeSpec | ast.Decl) -> tuple[str, int, ast.Struct | None]:
    match t:
        case ast.BaseType() if t.name in _ELEMENT_IDS:
            return t.name, 0, None
        case ast.StringType():
            kind = "wstring" if t.wide else "string"
            if t.bound is not None:
                return "bounded " + kind, t.bound, None
            return kind, 0, None
        case ast.Struct():
            return "nested", 0, t
        case ast.SequenceType():
            raise NotDescribable("sequences of sequences have no ROS 2 type")
        case ast.BaseType():
            raise NotDescribable(f"'{t.name}' has no ROS 2 type")
    what = getattr(t, "kind", type(t).__name__)
    raise NotDescribable(f"{what}s have no ROS 2 type")
