"""ROS 2 interface text (`.msg`, `.srv`, `.action`) -> its messages, as rosidl_adapter reads them.

The lines are parsed with `msg.lark`; this module gives them rosidl_adapter's meaning (Kilted,
`rosidl_adapter/parser.py`): the sections between `---` lines, field and constant types, names
checked against rosidl's patterns, and the comments: the lines starting with `#` at the top of a
section document the message, a comment line documents the next definition, an indented one the
definition before it, a unit in brackets (`# [m/s]`) becomes the definition's unit. Values stay
text here (`msg_values.py` reads them).
"""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import lark

from miro_gen.diagnostics import Diagnostics, SourcePos

PRIMITIVES = (
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
)  # fmt: skip
# rosidl_adapter's patterns (parser.py) for package, field, message and constant names.
PACKAGE_NAME = re.compile(r"(?!.*__)(?!.*_$)[a-z][a-z0-9_]*")
FIELD_NAME = PACKAGE_NAME
MESSAGE_NAME = re.compile(r"[A-Z][A-Za-z0-9]*")
CONSTANT_NAME = re.compile(r"[A-Z]([A-Z0-9_]?[A-Z0-9]+)*")
# What the sections of each kind of file are called (the message name's suffix).
SECTIONS = {
    "msg": ("",),
    "srv": ("_Request", "_Response"),
    "action": ("_Goal", "_Result", "_Feedback"),
}
_Tree = lark.Tree[lark.Token]
_UNIT = re.compile(r"(\s*\[([^,\]]+)\])")
_ARRAY = re.compile(r"\[(<=)?([^\]]*)\]$")


class MsgSyntaxError(Exception):
    """A line rosidl_adapter rejects; `pos` is where."""

    def __init__(self, pos: SourcePos, message: str) -> None:
        super().__init__(message)
        self.pos = pos
        self.message = message


@dataclass(frozen=True)
class MsgType:
    """A type as written in a definition: `int32`, `string<=8`, `geometry_msgs/Point[<=3]`."""

    base: str  # a primitive (PRIMITIVES) or a message name
    package: str | None  # the message's package; None for primitives
    string_bound: int | None = None
    array: str | None = None  # None, "fixed", "bounded" or "unbounded"
    size: int | None = None  # the array's size or the sequence's bound

    @property
    def primitive(self) -> bool:
        return self.package is None


@dataclass
class MsgDefinition:
    """A field (`kind` "field", with an optional default) or a constant (`kind` "constant")."""

    kind: str
    type: MsgType
    name: str
    value: str | None
    pos: SourcePos
    comments: list[str] = field(default_factory=list)
    unit: str | None = None


@dataclass
class MessageText:
    """One message of a file: a `.msg`, or a section of a `.srv` or `.action`."""

    name: str
    pos: SourcePos
    fields: list[MsgDefinition] = field(default_factory=list)
    constants: list[MsgDefinition] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)
    unit: str | None = None


@lru_cache(maxsize=1)
def _parser() -> lark.Lark:
    grammar = (Path(__file__).parent / "msg.lark").read_text(encoding="utf-8")
    return lark.Lark(grammar, parser="lalr", lexer="contextual", propagate_positions=False)


def read_messages(
    path: str, text: str, package: str, kind: str, name: str, diag: Diagnostics
) -> list[MessageText] | None:
    """The messages of interface file `path` (`kind` msg, srv or action, type `name` of
    `package`); None after reporting the first problem, as rosidl_adapter stops at it."""
    try:
        return _read(path, text, package, kind, name)
    except MsgSyntaxError as e:
        diag.error(e.pos, e.message)
        return None


def _read(path: str, text: str, package: str, kind: str, name: str) -> list[MessageText]:
    lines = text.replace("\t", " ").splitlines()  # as rosidl_adapter reads them
    try:
        tree = _parser().parse("\n".join(lines))
    except lark.exceptions.UnexpectedInput as e:
        line, col = e.line, e.column
        shown = lines[line - 1].strip() if 0 < line <= len(lines) else ""
        raise MsgSyntaxError(
            SourcePos(path, max(line, 1), max(col, 1)),
            f"cannot read '{shown}': a line holds `TYPE NAME [DEFAULT]`, `TYPE NAME=VALUE` "
            "or a comment",
        ) from None
    sections: list[list[_Tree]] = [[]]
    starts = [SourcePos(path, 1, 1)]
    for item in tree.children:
        assert isinstance(item, lark.Tree)
        if item.data == "separator":
            tok = item.children[0]
            assert isinstance(tok, lark.Token)
            sections.append([])
            starts.append(SourcePos(path, (tok.line or 0) + 1, 1))
        else:
            sections[-1].append(item)
    suffixes = SECTIONS[kind]
    if len(sections) != len(suffixes):
        what = {"msg": "a .msg file has no '---' line", "srv": "a .srv file has one '---' line "
                "between request and response", "action": "an .action file has two '---' "
                "lines between goal, result and feedback"}[kind]  # fmt: skip
        pos = starts[min(len(sections), len(suffixes)) if len(sections) > 1 else 0]
        raise MsgSyntaxError(pos, f"{len(sections) - 1} '---' lines: {what}")
    return [
        _message(path, items, package, name + suffix, start)
        for items, suffix, start in zip(sections, suffixes, starts, strict=True)
    ]


def _message(
    path: str, items: list[_Tree], package: str, name: str, start: SourcePos
) -> MessageText:
    msg = MessageText(name, start)
    rest = _file_comments(items, start.line, msg.comments)
    pending: list[str] = []
    last: MsgDefinition | None = None
    for item in rest:
        toks = [t for t in item.children if isinstance(t, lark.Token)]
        if item.data == "blank":
            continue
        if item.data == "comment":
            text = str(toks[0])
            body = text.lstrip(" \t").lstrip("#").rstrip()
            if text[0] in " \t":  # indented: documents the definition before it
                if last is not None:
                    last.comments.append(body)
            else:
                pending.append(body)
            continue
        last = _definition(path, item.data, toks, package)
        if toks[-1].type == "COMMENT":
            pending.append(str(toks[-1]).lstrip(" \t").lstrip("#").rstrip())
        last.comments += pending
        pending = []
        (msg.fields if last.kind == "field" else msg.constants).append(last)
    _check_unique(msg.fields, "field")
    _check_unique(msg.constants, "constant")
    msg.unit = _tidy(msg.comments)
    for d in (*msg.fields, *msg.constants):
        d.unit = _tidy(d.comments)
    return msg


def _file_comments(items: list[_Tree], first: int, into: list[str]) -> list[_Tree]:
    """Take the lines at the top of a section (from line `first`) that start with `#` into
    `into`, as they are (rosidl_adapter keeps their trailing blanks); the rest of the items."""
    for i, item in enumerate(items):
        tok = item.children[0]
        assert isinstance(tok, lark.Token)
        if item.data != "comment" or str(tok)[0] != "#" or tok.line != first + i:
            return items[i:]
        into.append(str(tok).lstrip("#"))
    return []


def _definition(path: str, kind: str, toks: list[lark.Token], package: str) -> MsgDefinition:
    type_tok, name_tok = toks[0], toks[1]
    pos = SourcePos(path, type_tok.line or 1, type_tok.column or 1)
    name_pos = SourcePos(path, name_tok.line or 1, (name_tok.column or 1) + _indent(name_tok))
    name = str(name_tok).strip()
    msg_type = parse_type(str(type_tok), package, pos)
    value: str | None = None
    if kind == "field":
        if not FIELD_NAME.fullmatch(name):
            raise MsgSyntaxError(
                name_pos,
                f"'{name}' is not a valid field name: lower case letters, digits and single "
                "underscores, starting with a letter, not ending with an underscore",
            )
        default = next((t for t in toks if t.type == "DEFAULT"), None)
        value = str(default).strip() if default is not None else None
        if value is not None and not msg_type.primitive:
            raise MsgSyntaxError(name_pos, f"field '{name}' of a message type has no default")
        return MsgDefinition("field", msg_type, name, value, pos)
    if not CONSTANT_NAME.fullmatch(name):
        raise MsgSyntaxError(
            name_pos,
            f"'{name}' is not a valid constant name: upper case letters, digits and single "
            "underscores, starting with a letter",
        )
    if not msg_type.primitive or msg_type.array is not None or msg_type.string_bound:
        raise MsgSyntaxError(pos, f"constant '{name}' must have a primitive type, not '{type_tok}'")
    value_tok = next((t for t in toks if t.type == "VALUE"), None)
    value = str(value_tok).strip() if value_tok is not None else ""
    return MsgDefinition("constant", msg_type, name, value, pos)


def _indent(tok: lark.Token) -> int:
    text = str(tok)
    return len(text) - len(text.lstrip(" \t"))


def parse_type(text: str, package: str, pos: SourcePos) -> MsgType:
    """A type as rosidl_adapter's `Type` reads it; a message name without a package is one of
    the file's own package."""
    array: str | None = None
    size: int | None = None
    base = text
    m = _ARRAY.search(text)
    if text.endswith("]"):
        if m is None:
            raise MsgSyntaxError(pos, f"type '{text}' ends with ']' but has no '['")
        base = text[: m.start()]
        if m.group(2) == "" and m.group(1) is None:
            array = "unbounded"
        else:
            array = "bounded" if m.group(1) else "fixed"
            size = _positive(m.group(2), pos, f"the size of array type '{text}'")
    bound: int | None = None
    for prim in ("string", "wstring"):
        if base.startswith(prim + "<="):
            bound = _positive(base[len(prim) + 2 :], pos, f"the bound of string type '{text}'")
            base = prim
    if base in PRIMITIVES:
        return MsgType(base, None, bound, array, size)
    if base in ("time", "duration"):
        raise MsgSyntaxError(
            pos,
            f"'{base}' is ROS 1's; ROS 2 writes builtin_interfaces/{base.capitalize()}",
        )
    parts = base.split("/")
    if len(parts) > 2 or not all(parts):
        raise MsgSyntaxError(pos, f"'{base}' is not a type: write NAME or PACKAGE/NAME")
    pkg, name = (parts[0], parts[1]) if len(parts) == 2 else (package, parts[0])
    if not PACKAGE_NAME.fullmatch(pkg):
        raise MsgSyntaxError(pos, f"'{pkg}' is not a valid package name")
    if not MESSAGE_NAME.fullmatch(name):
        raise MsgSyntaxError(
            pos, f"'{name}' is not a valid message name: a capital letter, then letters and digits"
        )
    return MsgType(name, pkg, None, array, size)


def _positive(text: str, pos: SourcePos, what: str) -> int:
    if not text.isdigit() or int(text) <= 0:
        raise MsgSyntaxError(pos, f"{what} must be an integer above 0")
    return int(text)


def _check_unique(defs: list[MsgDefinition], what: str) -> None:
    seen: set[str] = set()
    for d in defs:
        if d.name in seen:
            raise MsgSyntaxError(d.pos, f"{what} '{d.name}' is defined twice")
        seen.add(d.name)


def _tidy(lines: list[str]) -> str | None:
    """rosidl_adapter's `process_comments`: take the one unit in brackets out of the comment
    lines, drop leading, trailing and repeated empty lines, and dedent (in place); the unit."""
    unit = None
    matches = _UNIT.findall("\n".join(lines))
    if len(matches) == 1:
        unit = matches[0][1]
        lines[:] = [line.replace(matches[0][0], "") for line in lines]
    while lines and lines[0] == "":
        del lines[0]
    while lines and lines[-1] == "":
        del lines[-1]
    i = 1
    while i < len(lines):
        if lines[i] == "" and lines[i - 1] == "":
            del lines[i]
            continue
        i += 1
    if lines:
        lines[:] = textwrap.dedent("\n".join(lines)).split("\n")
    return unit
