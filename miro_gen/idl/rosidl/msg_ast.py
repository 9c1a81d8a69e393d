"""The messages of a ROS 2 interface file -> the IDL definitions rosidl_adapter writes for them.

rosidl_adapter (Kilted, `resource/struct.idl.em`) turns each message into, inside
`module <package> { module <msg|srv|action> { ... } }`: a typedef per fixed-size array type
(`typedef double double__9[9];`, and `typedef pkg::msg::T pkg__msg__T;` before an array of a
message type), a module `<Name>_Constants` holding the constants, and the struct, whose members
carry `@verbatim (language="comment", text=...)`, `@default (value=...)` and `@unit (value=...)`.
An empty message gets the member `uint8 structure_needs_at_least_one_member`. The nodes built
here are the ones the IDL parser builds from that `.idl`; the resolver completes them.
"""

from __future__ import annotations

import math

from miro_gen.diagnostics import Diagnostics, SourcePos
from miro_gen.idl import ast
from miro_gen.idl.rosidl.msg_parser import MessageText, MsgDefinition, MsgType
from miro_gen.idl.rosidl.msg_values import ValueProblem, idl_string, idl_value, parse_value

# rosidl_adapter's MSG_TYPE_TO_IDL, with the IDL types spelled as the parser names them.
IDL_TYPES = {
    "bool": "boolean", "byte": "octet", "char": "uint8", "int8": "int8", "uint8": "uint8",
    "int16": "short", "uint16": "unsigned short", "int32": "long", "uint32": "unsigned long",
    "int64": "long long", "uint64": "unsigned long long", "float32": "float",
    "float64": "double",
}  # fmt: skip
# How rosidl_adapter spells them in typedef names (`int16__3`).
IDL_SPELLING = {
    "bool": "boolean", "byte": "octet", "char": "uint8", "float32": "float", "float64": "double",
}  # fmt: skip
EMPTY_MEMBER = "structure_needs_at_least_one_member"


def file_definitions(
    package: str, kind: str, messages: list[MessageText], diag: Diagnostics
) -> list[ast.Definition]:
    """`module <package> { module <kind> { ... } }` for the messages of one file."""
    inner: list[ast.Definition] = []
    for msg in messages:
        inner += _message(package, kind, msg, diag)
    pos = messages[0].pos
    return [ast.Module(package, pos, [ast.Module(kind, pos, inner)])]


def _message(package: str, kind: str, msg: MessageText, diag: Diagnostics) -> list[ast.Definition]:
    out: list[ast.Definition] = []
    typedefs: dict[str, tuple[ast.TypeSpec, int | None, SourcePos]] = {}
    for f in msg.fields:
        if f.type.array == "fixed":
            base = _spelling(f.type, "::")
            alias = base.replace("::", "__")
            if alias != base and alias not in typedefs:
                typedefs[alias] = (_element_type(f.type, f.pos), None, f.pos)
            name = _array_alias(f.type)
            if name not in typedefs:
                elem = _named(alias, f.pos) if alias != base else _element_type(f.type, f.pos)
                typedefs[name] = (elem, f.type.size, f.pos)
    for name, (typ, size, pos) in typedefs.items():
        dims: list[ast.Expr] = [ast.Literal("int", size, pos)] if size is not None else []
        out.append(ast.TypedefGroup(typ, [(name, pos, dims)], pos))
    if msg.constants:
        consts = [c for c in (_constant(c, diag) for c in msg.constants) if c is not None]
        out.append(ast.Module(msg.name + "_Constants", msg.constants[0].pos, list(consts)))
    members = [m for m in (_member(f, diag) for f in msg.fields) if m is not None]
    if not msg.fields:
        members = [ast.Member(EMPTY_MEMBER, ast.BaseType("uint8"), [], msg.pos)]
    struct = ast.Struct(msg.name, msg.pos, members=members)
    struct.annotations = _verbatim(msg.comments, msg.pos)
    out.append(struct)
    return out


def _constant(c: MsgDefinition, diag: Diagnostics) -> ast.Const | None:
    value = _value(c, diag)
    if value is None:
        return None
    const = ast.Const(c.name, c.pos, type=_element_type(c.type, c.pos), expr=value)
    const.annotations = _verbatim(c.comments, c.pos)
    return const


def _member(f: MsgDefinition, diag: Diagnostics) -> ast.Member | None:
    annotations = _verbatim(f.comments, f.pos)
    if f.value is not None:
        value = _value(f, diag)
        if value is None:
            return None
        annotations.append(_annotation("default", {"value": value}, f.pos))
    if f.unit is not None:
        unit = ast.Literal("string", _text(f.unit, f.pos, diag), f.pos)
        annotations.append(_annotation("unit", {"value": unit}, f.pos))
    t = f.type
    typ: ast.TypeSpec
    if t.array == "fixed":
        typ = _named(_array_alias(t), f.pos)
    elif t.array is not None:
        typ = ast.SequenceType(_element_type(t, f.pos), _size(t, f.pos), f.pos)
    else:
        typ = _element_type(t, f.pos)
    return ast.Member(f.name, typ, [], f.pos, annotations)


def _value(d: MsgDefinition, diag: Diagnostics) -> ast.Expr | None:
    assert d.value is not None
    try:
        value = idl_value(d.type, parse_value(d.type, d.value))
    except ValueProblem as e:
        diag.error(d.pos, f"{d.kind} '{d.name}': {e}")
        return None
    kind = {bool: "bool", int: "int", float: "float", str: "string"}[type(value)]
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if number and math.copysign(1, value) < 0:  # type: ignore[arg-type]
        # `-5`: a minus and a literal, as the parser reads it
        return ast.UnaryOp("-", ast.Literal(kind, -value, d.pos), d.pos)  # type: ignore[operator]
    return ast.Literal(kind, value, d.pos)


def _text(text: str, pos: SourcePos, diag: Diagnostics) -> str:
    try:
        return idl_string(text)
    except ValueProblem as e:
        diag.error(pos, str(e))
        return text


def _verbatim(lines: list[str], pos: SourcePos) -> list[ast.Annotation]:
    """`@verbatim (language="comment", text=...)` for comment lines, or nothing."""
    if not lines:
        return []
    try:
        text = "\n".join(idl_string(line) for line in lines)
    except ValueProblem:  # a comment rosidl_adapter would choke on: kept as it is
        text = "\n".join(lines)
    args: dict[str, ast.Expr] = {
        "language": ast.Literal("string", "comment", pos),
        "text": ast.Literal("string", text, pos),
    }
    return [_annotation("verbatim", args, pos)]


def _annotation(name: str, args: dict[str, ast.Expr], pos: SourcePos) -> ast.Annotation:
    return ast.Annotation(ast.ScopedName((name,), False, pos), args, pos)


def _element_type(t: MsgType, pos: SourcePos) -> ast.TypeSpec:
    """The type of one value of `t` (its element, for arrays and sequences)."""
    if t.package is not None:
        return ast.NamedType(ast.ScopedName((t.package, "msg", t.base), False, pos))
    if t.base in ("string", "wstring"):
        bound = ast.Literal("int", t.string_bound, pos) if t.string_bound is not None else None
        return ast.StringType(t.base == "wstring", bound, pos)
    return ast.BaseType(IDL_TYPES[t.base])


def _size(t: MsgType, pos: SourcePos) -> ast.Expr | None:
    return ast.Literal("int", t.size, pos) if t.size is not None else None


def _named(name: str, pos: SourcePos) -> ast.NamedType:
    return ast.NamedType(ast.ScopedName((name,), False, pos))


def _spelling(t: MsgType, sep: str) -> str:
    """The element type as rosidl_adapter writes it (`double`, `string<8>`, `pkg::msg::T`)."""
    if t.package is not None:
        return sep.join((t.package, "msg", t.base))
    name = IDL_SPELLING.get(t.base, t.base)
    return f"{name}<{t.string_bound}>" if t.string_bound is not None else name


def _array_alias(t: MsgType) -> str:
    """The typedef name of a fixed-size array type: `double__9`, `string__8__3`,
    `pkg__msg__T__3` (rosidl_adapter's `get_idl_type_identifier`)."""
    spelled = f"{_spelling(t, '::')}[{t.size}]"
    for old, new in (("::", "__"), ("<", "__"), (">", ""), ("[", "__"), ("]", "")):
        spelled = spelled.replace(old, new)
    return spelled
