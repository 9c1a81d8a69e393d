"""The data schema of a generated type (`cls._data_schema`, the flattened IDL text
miro_gen/codegen/schema.py writes) read back into structs and their fields (no I/O).

The DDS side needs a type's shape to describe it to peers as XTypes (ros2/xtypes.py); the run
time never imports the compiler, and the schema is a small, regular subset of IDL: modules,
structs, typedefs, enums and unions, with literal bounds. Typedefs are followed here (ROS 2's
type descriptions have none: `double[9]` is an array member, not an alias).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

_TOKENS = re.compile(r"\s*(?:(?P<word>[A-Za-z_][A-Za-z0-9_]*(?:::[A-Za-z_][A-Za-z0-9_]*)*)"
                     r"|(?P<num>\d+)|(?P<punct>[{};<>,\[\]:=()'-]))")  # fmt: skip
_TWO_WORD = {"long long", "unsigned short", "unsigned long", "unsigned long long", "long double"}


class SchemaError(ValueError):
    """A data schema this reader does not take (the message says what and where)."""


@dataclass(frozen=True)
class Primitive:
    name: str  # as IDL spells it: "unsigned long", "uint8", "double", "boolean", ...


@dataclass(frozen=True)
class String:
    bound: int | None = None
    wide: bool = False


@dataclass(frozen=True)
class Sequence:
    element: TypeRef
    bound: int | None = None


@dataclass(frozen=True)
class Array:
    element: TypeRef
    dims: tuple[int, ...]


@dataclass(frozen=True)
class Named:
    scoped: str  # a struct of the schema, `a::b::Name`


TypeRef = Primitive | String | Sequence | Array | Named


@dataclass(frozen=True)
class Member:
    name: str
    type: TypeRef


@dataclass
class Struct:
    scoped: str
    members: list[Member] = field(default_factory=list)


@dataclass
class Schema:
    """The structs of a schema by scoped name, in the order declared (dependencies first)."""

    structs: dict[str, Struct]

    @property
    def top(self) -> Struct:
        """The type the schema is of: the last struct declared."""
        return next(reversed(self.structs.values()))


def read(text: str) -> Schema:
    return _Reader(text).schema()


class _Reader:
    def __init__(self, text: str) -> None:
        self.tokens: list[str] = []
        pos = 0
        text = text.rstrip()
        while pos < len(text):
            m = _TOKENS.match(text, pos)
            if m is None or m.end() == pos:
                raise SchemaError(f"unexpected text at {pos}: {text[pos : pos + 20]!r}")
            self.tokens.append(m.group(m.lastgroup or "punct"))
            pos = m.end()
        self.i = 0
        self.scope: list[str] = []
        self.typedefs: dict[str, TypeRef] = {}
        self.structs: dict[str, Struct] = {}

    def schema(self) -> Schema:
        while self.i < len(self.tokens):
            self.definition()
        if not self.structs:
            raise SchemaError("the schema declares no struct")
        return Schema(self.structs)

    def peek(self) -> str:
        return self.tokens[self.i] if self.i < len(self.tokens) else ""

    def take(self, want: str | None = None) -> str:
        tok = self.peek()
        if not tok or (want is not None and tok != want):
            raise SchemaError(f"expected {want or 'more'} at token {self.i}, found {tok!r}")
        self.i += 1
        return tok

    def definition(self) -> None:
        word = self.take()
        if word == "module":
            self.scope.append(self.take())
            self.take("{")
            while self.peek() != "}":
                self.definition()
            self.take("}")
            self.take(";")
            self.scope.pop()
        elif word == "struct":
            name = self.take()
            if self.peek() == ";":  # a forward declaration
                self.take(";")
                return
            if self.peek() == ":":
                raise SchemaError(f"struct {name}: inheritance has no ROS 2 form")
            struct = Struct("::".join([*self.scope, name]))
            self.take("{")
            while self.peek() != "}":
                t = self.type_spec()
                member = self.take()
                struct.members.append(Member(member, self.dims(t)))
                self.take(";")
            self.take("}")
            self.take(";")
            self.structs[struct.scoped] = struct
        elif word == "typedef":
            t = self.type_spec()
            name = self.take()
            self.typedefs["::".join([*self.scope, name])] = self.dims(t)
            self.take(";")
        else:
            raise SchemaError(f"{word!r} declarations have no ROS 2 form")

    def dims(self, t: TypeRef) -> TypeRef:
        dims: list[int] = []
        while self.peek() == "[":
            self.take("[")
            dims.append(int(self.take()))
            self.take("]")
        return Array(t, tuple(dims)) if dims else t

    def type_spec(self) -> TypeRef:
        word = self.take()
        if word in ("string", "wstring"):
            bound = None
            if self.peek() == "<":
                self.take("<")
                bound = int(self.take())
                self.take(">")
            return String(bound, word == "wstring")
        if word == "sequence":
            self.take("<")
            element = self.type_spec()
            bound = None
            if self.peek() == ",":
                self.take(",")
                bound = int(self.take())
            self.take(">")
            return Sequence(element, bound)
        if word in ("unsigned", "long"):
            while f"{word} {self.peek()}" in _TWO_WORD:
                word = f"{word} {self.take()}"
            return Primitive(word)
        if "::" in word or word in self.structs or self._scoped(word) is not None:
            scoped = self._scoped(word) or word
            if scoped in self.typedefs:
                return self.typedefs[scoped]
            return Named(scoped)
        return Primitive(word)

    def _scoped(self, name: str) -> str | None:
        """The scoped name a (possibly relative) name refers to, searching outwards."""
        for depth in range(len(self.scope), -1, -1):
            scoped = "::".join([*self.scope[:depth], name])
            if scoped in self.structs or scoped in self.typedefs:
                return scoped
        return None
