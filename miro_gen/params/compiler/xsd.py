"""An XML Schema (1.0) of run-time documents for a set of parameter classes (`--xsd`).

Every element of a run-time document is a `<parameter>`, told apart by its `name=`; XML Schema
1.0 cannot give elements of one name different types by an attribute, so the schema is built
level by level: the `<parameter>` children of an element may carry the names (both spellings)
and values of every parameter that can appear at that level, and their own children those of the
next level. Editors then complete parameter names and flag misspelt ones, misplaced nesting and
values of the wrong type where a level has one type; `ConfigDocument` checks the rest.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from miro_gen.codegen.render import environment
from miro_gen.params.runtime import Config, Struct, codecs, layout_of

Slot = tuple[str | None, codecs.Codec]  # (name=, codec) of an element that may appear


@dataclass
class XsdType:
    name: str
    names: list[str] = field(default_factory=list)  # allowed name= values
    named: str = "optional"  # "required", "optional" or "prohibited"
    value: str | None = None  # the XML Schema type of value=, or None (no value)
    children: str | None = None  # the type of <parameter> children


@dataclass
class XsdEnum:
    name: str
    choices: tuple[str, ...]


class SchemaBuilder:
    def __init__(self) -> None:
        self.types: list[XsdType] = []
        self.enums: list[XsdEnum] = []
        self._by_key: dict[tuple[str, ...], str] = {}
        self._enum_by_choices: dict[tuple[str, ...], str] = {}

    def value_type(self, codec: codecs.Codec) -> str | None:
        if isinstance(codec, codecs.Enum):
            key = codec.choices
            if key not in self._enum_by_choices:
                name = f"Enum{len(self.enums)}"
                self._enum_by_choices[key] = name
                self.enums.append(XsdEnum(name, key))
            return self._enum_by_choices[key]
        if isinstance(codec, codecs.Scalar):
            return codec.xsd
        if isinstance(codec, codecs.Vector) and (codec.compact or codec.matrix):
            return "xs:string"
        return None

    def children_of(self, codec: codecs.Codec) -> list[Slot]:
        if isinstance(codec, Struct):
            out: list[Slot] = []
            for f in codec.layout.fields:
                out.append((f.xml, f.codec))
                lower = f.xml[:1].lower() + f.xml[1:]
                if lower != f.xml:
                    out.append((lower, f.codec))
            return out
        if isinstance(codec, codecs.Vector):
            return [(None, codec.element)]
        return []

    def type_for(self, slots: list[Slot]) -> str:
        key = tuple(sorted({f"{n}|{_key(c)}" for n, c in slots}))
        if key in self._by_key:
            return self._by_key[key]
        t = XsdType(name=f"Level{len(self.types)}")
        self._by_key[key] = t.name
        self.types.append(t)
        names = sorted({n for n, _ in slots if n is not None})
        unnamed = any(n is None for n, _ in slots)
        t.names = names
        t.named = "prohibited" if not names else ("optional" if unnamed else "required")
        values = {self.value_type(c) for _, c in slots}
        given = {v for v in values if v is not None}
        if given:
            t.value = given.pop() if len(given) == 1 else "xs:string"
        children = [s for _, c in slots for s in self.children_of(c)]
        if children:
            t.children = self.type_for(children)
        return t.name


def _key(codec: codecs.Codec) -> str:
    """A structural key, so that the same parameter type gives the same schema type."""
    if isinstance(codec, Struct):
        return f"S:{codec.layout.cls.__module__}.{codec.layout.cls.__qualname__}"
    if isinstance(codec, codecs.Vector):
        return f"V{'s' if codec.unique else ''}:{_key(codec.element)}"
    if isinstance(codec, codecs.Enum):
        return "E:" + ",".join(codec.choices)
    return f"X:{codec.label}"


def render_xsd(classes: Iterable[type[Config]]) -> str:
    """The schema text for run-time documents using these classes."""
    builder = SchemaBuilder()
    slots: list[Slot] = []
    for cls in classes:
        for f in layout_of(cls).fields:
            slots.append((f.xml, f.codec))
            slots.append((f.xml[:1].lower() + f.xml[1:], f.codec))
    top = builder.type_for(slots) if slots else None
    return (
        environment()
        .get_template("params/schema.xsd.j2")
        .render(top=top, types=builder.types, enums=builder.enums)
    )
