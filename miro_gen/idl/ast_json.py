"""The resolved AST as JSON, in the shape DESIGN.md specifies (`miro-idl --ast-json`)."""

from __future__ import annotations

import json
from decimal import Decimal
from typing import Any

from miro_gen.idl import ast

JsonObj = dict[str, Any]
# The documents are trees of fresh dicts and lists: no cycle to look for.
_ENCODER = json.JSONEncoder(ensure_ascii=False, check_circular=False)


def type_string(t: Any) -> str:
    """A type in IDL spelling; named types by their full scoped name (typedefs not expanded)."""
    if isinstance(t, ast.BaseType):
        return t.name
    if isinstance(t, ast.NamedType):
        if t.decl is not None:
            return t.decl.scoped_name
        return "::".join(t.name.parts)
    if isinstance(t, ast.StringType):
        base = "wstring" if t.wide else "string"
        return f"{base}<{t.bound}>" if t.bound is not None else base
    if isinstance(t, ast.SequenceType):
        elem = type_string(t.element)
        return f"sequence<{elem}, {t.bound}>" if t.bound is not None else f"sequence<{elem}>"
    if isinstance(t, ast.FixedType):
        return f"fixed<{t.digits}, {t.scale}>" if t.digits is not None else "fixed"
    if isinstance(t, ast.MapType):
        inner = f"{type_string(t.key)}, {type_string(t.value)}"
        return f"map<{inner}, {t.bound}>" if t.bound is not None else f"map<{inner}>"
    if isinstance(t, ast.Decl):
        return t.scoped_name
    if t is None:
        return "void"
    raise TypeError(f"not a type: {t!r}")  # pragma: no cover


def const_json(v: Any) -> Any:
    if isinstance(v, ast.EnumValue):
        return v.scoped_name
    if isinstance(v, Decimal):
        return str(v)
    return v


def annotations_json(anns: list[ast.Annotation]) -> list[JsonObj]:
    return [
        {"name": "::".join(a.name.parts), "params": {k: const_json(v) for k, v in a.params.items()}}
        for a in anns
    ]


def _member(m: ast.Member, with_public: bool = False) -> JsonObj:
    out: JsonObj = {
        "name": m.name,
        "type": type_string(m.type),
        "dims": list(m.dims),
        "annotations": annotations_json(m.annotations),
    }
    if with_public:
        out["public"] = m.public
    return out


def _operation(op: ast.Operation) -> JsonObj:
    return {
        "name": op.name,
        "oneway": op.oneway,
        "returns": type_string(op.returns),
        "params": [
            {"mode": p.mode, "name": p.name, "type": type_string(p.type)} for p in op.params
        ],
        "raises": [e.scoped_name for e in op.raises],
        "contexts": list(op.contexts),
    }


def _attribute(a: ast.Attribute) -> JsonObj:
    return {
        "name": a.name,
        "type": type_string(a.type),
        "readonly": a.readonly,
        "get_raises": [e.scoped_name for e in a.get_raises],
        "set_raises": [e.scoped_name for e in a.set_raises],
    }


def declaration_json(d: ast.Decl) -> JsonObj:
    out: JsonObj = {
        "kind": d.kind,
        "name": d.scoped_name,
        "repo_id": d.repo_id,
        "file": d.pos.path,
        "line": d.pos.line,
        "doc": d.doc,
        "annotations": annotations_json(d.annotations),
    }
    if isinstance(d, ast.Forward):
        out["of"] = d.of
    elif isinstance(d, ast.Struct):
        out["members"] = [_member(m) for m in d.members]
        out["base"] = d.base.scoped_name if d.base is not None else None
    elif isinstance(d, ast.Exception_):
        out["members"] = [_member(m) for m in d.members]
    elif isinstance(d, ast.Union_):
        out["discriminator"] = type_string(d.switch_type)
        out["cases"] = [
            {
                "labels": ["default" if v is None else const_json(v) for v in c.labels],
                "name": c.name,
                "type": type_string(c.type),
                "dims": list(c.dims),
            }
            for c in d.cases
        ]
    elif isinstance(d, ast.Enum):
        out["enumerators"] = [e.name for e in d.enumerators]
    elif isinstance(d, ast.Typedef):
        out["type"] = type_string(d.type)
        out["dims"] = list(d.dims)
    elif isinstance(d, ast.Const):
        out["type"] = type_string(d.type)
        out["value"] = const_json(d.value)
    elif isinstance(d, ast.Interface):
        out["bases"] = [b.scoped_name for b in d.base_refs]
        out["abstract"] = d.abstract
        out["local"] = d.local
        out["operations"] = [_operation(op) for op in d.operations]
        out["attributes"] = [_attribute(a) for a in d.attributes]
    elif isinstance(d, ast.ValueType):
        out["bases"] = [b.scoped_name for b in d.base_refs]
        out["supports"] = [s.scoped_name for s in d.supports_refs]
        out["abstract"] = d.abstract
        out["custom"] = d.custom
        out["truncatable"] = d.truncatable
        out["members"] = [_member(m, with_public=True) for m in d.members]
        out["operations"] = [_operation(op) for op in d.operations]
        out["attributes"] = [_attribute(a) for a in d.attributes]
        out["factories"] = [
            {
                "name": f.name,
                "params": [
                    {"mode": p.mode, "name": p.name, "type": type_string(p.type)} for p in f.params
                ],
                "raises": [e.scoped_name for e in f.raises],
            }
            for f in d.factories
        ]
    elif isinstance(d, ast.ValueBox):
        out["type"] = type_string(d.type)
    return out


def specifications_json(files: list[str], specs: list[ast.Specification]) -> JsonObj:
    """The AST JSON document for the given command-line files and their resolved units.

    A declaration reached by several units (a shared include) is listed once. A struct of a
    ROS 2 interface also has its RIHS01 type hash (`ros2_type_hash`).
    """
    seen: set[tuple[str, int, int, str, str]] = set()
    declarations: list[JsonObj] = []
    for spec in specs:
        for d in spec.declarations:
            key = (d.pos.path, d.pos.line, d.pos.col, d.kind, d.scoped_name)
            if key in seen:
                continue
            seen.add(key)
            out = declaration_json(d)
            ros2_hash = spec.ros2_hashes.get(d.scoped_name)
            if ros2_hash is not None and isinstance(d, ast.Struct):
                out["ros2_type_hash"] = ros2_hash
            declarations.append(out)
    return {"files": list(files), "declarations": declarations}


def dumps(doc: JsonObj) -> str:
    """Serialise the AST JSON document: valid JSON with one declaration per line.

    One line per declaration keeps the output greppable and diffable while letting the C encoder
    do the work (an indented dump is several times slower on large files).
    """
    encode = _ENCODER.encode  # one encoder: json.dumps with options makes one per call
    head = encode(doc["files"])
    decls = ",\n".join(map(encode, doc["declarations"]))
    body = f"\n{decls}\n" if decls else ""
    return f'{{"files": {head}, "declarations": [{body}]}}\n'
