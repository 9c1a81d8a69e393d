"""TypeCodes from data schemas: the self-contained IDL text every generated type carries.

The run time never imports the compilers (docs/ARCHITECTURE.md), so this reads the schema
itself. It needs little: a data schema is IDL that `miro_gen.codegen.schema` writes in one
regular form, holding only modules, structs (with an IDL 4 base), exceptions (written as
structs), unions, enums, typedefs and forward declarations, with literal bounds and labels,
fully scoped names, and `miro::ObjectRef` standing for object references. Anything else is
refused with BAD_PARAM naming it.
"""

from __future__ import annotations

import re
from typing import Any

from miro_gen.corba.typecode import K, TypeCode, objref_tc, simple, string_tc
from miro_gen.exceptions import BAD_PARAM

OBJECT_REF = "miro::ObjectRef"
_OBJECT = "IDL:omg.org/CORBA/Object:1.0"
_TOKEN = re.compile(
    r"\s*(?:(::|[{};:<>,\[\]()])|('(?:\\.|[^'])*')|(-?[0-9][0-9A-Fa-fxX]*)|([A-Za-z_]\w*))"
)
_BASE = {
    "short": K.tk_short, "unsigned short": K.tk_ushort, "long": K.tk_long,
    "unsigned long": K.tk_ulong, "long long": K.tk_longlong,
    "unsigned long long": K.tk_ulonglong, "float": K.tk_float, "double": K.tk_double,
    "long double": K.tk_longdouble, "boolean": K.tk_boolean, "char": K.tk_char,
    "wchar": K.tk_wchar, "octet": K.tk_octet, "int8": K.tk_octet, "uint8": K.tk_octet,
    "int16": K.tk_short, "uint16": K.tk_ushort, "int32": K.tk_long, "uint32": K.tk_ulong,
    "int64": K.tk_longlong, "uint64": K.tk_ulonglong, "any": K.tk_any,
}  # fmt: skip


def _tokens(text: str) -> list[str]:
    out = []
    pos = 0
    text = text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise BAD_PARAM(f"data schema: cannot read {text[pos : pos + 20]!r}")
        out.append(next(g for g in m.groups() if g is not None))
        pos = m.end()
    return out


class SchemaReader:
    """The named types of one data schema, as TypeCodes (`types[scoped name]`);
    `repo_ids` gives the real repository ids of types (schemas drop `#pragma prefix`)."""

    def __init__(self, text: str, repo_ids: dict[str, str] | None = None) -> None:
        self.t = _tokens(text)
        self.i = 0
        self.repo_ids = repo_ids or {}
        self.types: dict[str, TypeCode] = {}
        self.enumerators: dict[str, int] = {}  # scoped enumerator -> ordinal
        self.scope: list[str] = []
        while self.i < len(self.t):
            self._definition()

    # ---- tokens -------------------------------------------------------------------------------

    def _peek(self, ahead: int = 0) -> str:
        j = self.i + ahead
        return self.t[j] if j < len(self.t) else ""

    def _next(self) -> str:
        tok = self._peek()
        if not tok:
            raise BAD_PARAM("data schema: ends too early")
        self.i += 1
        return tok

    def _expect(self, tok: str) -> None:
        got = self._next()
        if got != tok:
            raise BAD_PARAM(f"data schema: expected {tok!r}, found {got!r}")

    def _scoped_name(self) -> str:
        parts = [self._next()]
        while self._peek() == "::":
            self.i += 1
            parts.append(self._next())
        return "::".join(parts)

    # ---- declarations ---------------------------------------------------------------------------

    def _declare(self, name: str, kind: K) -> TypeCode:
        scoped = "::".join((*self.scope, name))
        tc = self.types.get(scoped)
        if tc is None:
            repo_id = self.repo_ids.get(scoped) or f"IDL:{scoped.replace('::', '/')}:1.0"
            tc = self.types[scoped] = TypeCode(kind, repo_id, name)
        tc.kind = kind
        return tc

    def _definition(self) -> None:
        word = self._next()
        if word == "module":
            self.scope.append(self._next())
            self._expect("{")
            while self._peek() != "}":
                self._definition()
            self._expect("}")
            self._expect(";")
            self.scope.pop()
        elif word in ("struct", "union") and self._peek(1) == ";":  # forward declaration
            self._declare(self._next(), K.tk_struct if word == "struct" else K.tk_union)
            self._expect(";")
        elif word == "struct":
            self._struct()
        elif word == "union":
            self._union()
        elif word == "enum":
            self._enum()
        elif word == "typedef":
            content = self._type()
            name = self._next()
            tc = self._declare(name, K.tk_alias)
            tc.content = self._dims(content)
            self._expect(";")
        else:
            raise BAD_PARAM(f"data schema: {word!r} has no TypeCode here")

    def _struct(self) -> None:
        tc = self._declare(self._next(), K.tk_struct)
        members: list[tuple[str, TypeCode]] = []
        if self._peek() == ":":
            self.i += 1
            base = self._named(self._scoped_name())
            members += base.members
        self._expect("{")
        while self._peek() != "}":
            member = self._type()
            name = self._next()
            members.append((name, self._dims(member)))
            self._expect(";")
        self._expect("}")
        self._expect(";")
        tc.members = members

    def _union(self) -> None:
        tc = self._declare(self._next(), K.tk_union)
        self._expect("switch")
        self._expect("(")
        tc.discriminator = self._type()
        self._expect(")")
        self._expect("{")
        while self._peek() != "}":
            labels: list[Any] = []
            while self._peek() in ("case", "default"):
                if self._next() == "default":
                    labels.append(None)
                else:
                    labels.append(self._label())
                self._expect(":")
            member = self._type()
            name = self._next()
            member = self._dims(member)
            self._expect(";")
            octet = tc.discriminator.resolved().kind == K.tk_octet  # int8 goes as an octet
            for label in labels:
                if label is None:
                    tc.default_index = len(tc.cases)
                    label = 0
                tc.cases.append((label & 0xFF if octet else label, name, member))
        self._expect("}")
        self._expect(";")

    def _enum(self) -> None:
        tc = self._declare(self._next(), K.tk_enum)
        self._expect("{")
        while True:
            name = self._next()
            self.enumerators["::".join((*self.scope, name))] = len(tc.enumerators)
            tc.enumerators.append(name)
            if self._next() == "}":
                break
        self._expect(";")

    def _label(self) -> Any:
        tok = self._peek()
        if tok.startswith("'"):
            self.i += 1
            body = tok[1:-1]
            if body.startswith("\\x"):
                return chr(int(body[2:], 16))
            return body[1:] if body.startswith("\\") else body
        if tok in ("TRUE", "FALSE"):
            self.i += 1
            return tok == "TRUE"
        if tok[:1].isdigit() or tok.startswith("-"):
            self.i += 1
            return int(tok, 0)
        name = self._scoped_name()
        if name not in self.enumerators:
            raise BAD_PARAM(f"data schema: unknown union label {name}")
        return self.enumerators[name]

    # ---- types ----------------------------------------------------------------------------------

    def _type(self) -> TypeCode:
        tok = self._peek()
        if tok in ("unsigned", "long"):
            words = [self._next()]
            while self._peek() in ("long", "short", "double") and " ".join(words) != "long double":
                words.append(self._next())
            return simple(_BASE[" ".join(words)])
        if tok in ("string", "wstring"):
            self.i += 1
            bound = self._bound() if self._peek() == "<" else 0
            return string_tc(bound, tok == "wstring")
        if tok == "sequence":
            self.i += 1
            self._expect("<")
            element = self._type()
            bound = 0
            if self._peek() == ",":
                self.i += 1
                bound = int(self._next(), 0)
            self._expect(">")
            return TypeCode(K.tk_sequence, content=element, length=bound)
        if tok in _BASE:
            self.i += 1
            return simple(_BASE[tok])
        if tok in ("fixed", "map"):
            raise BAD_PARAM(f"data schema: {tok} has no TypeCode here")
        return self._named(self._scoped_name())

    def _bound(self) -> int:
        self._expect("<")
        n = int(self._next(), 0)
        self._expect(">")
        return n

    def _named(self, name: str) -> TypeCode:
        if name == OBJECT_REF:
            return objref_tc(_OBJECT)
        tc = self.types.get(name)
        if tc is None:
            raise BAD_PARAM(f"data schema: {name} is used before it is declared")
        return tc

    def _dims(self, tc: TypeCode) -> TypeCode:
        dims = []
        while self._peek() == "[":
            self.i += 1
            dims.append(int(self._next(), 0))
            self._expect("]")
        for n in reversed(dims):
            tc = TypeCode(K.tk_array, content=tc, length=n)
        return tc
