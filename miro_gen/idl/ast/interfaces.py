"""Interfaces and value types, and what they hold: operations and their parameters,
attributes, factories, state members; value boxes."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from miro_gen.diagnostics import SourcePos
from miro_gen.idl.ast.declarations import Decl, Exception_, Member
from miro_gen.idl.ast.expressions import Annotation, Expr, Node, ScopedName
from miro_gen.idl.ast.type_specs import BaseType, TypeSpec

if TYPE_CHECKING:
    from miro_gen.idl.ast import Definition


class Param(Node):
    """An operation or factory parameter."""

    __slots__ = ("annotations", "doc", "mode", "name", "pos", "type")

    def __init__(
        self,
        mode: str,
        type: TypeSpec,
        name: str,
        pos: SourcePos,
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
    ) -> None:
        self.mode = mode  # in, out, inout
        self.type = type
        self.name = name
        self.pos = pos
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc


class Operation(Node):
    """An interface operation; `returns` is None for void."""

    __slots__ = (
        "annotations", "contexts", "doc", "name", "oneway", "params", "pos", "raises",
        "raises_names", "returns",
    )  # fmt: skip

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        oneway: bool,
        returns: TypeSpec | None,
        params: list[Param],
        raises_names: list[ScopedName],
        contexts: list[str],
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
        raises: list[Exception_] | None = None,
    ) -> None:
        self.name = name
        self.pos = pos
        self.oneway = oneway
        self.returns = returns
        self.params = params
        self.raises_names = raises_names
        self.contexts = contexts
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc
        self.raises: list[Exception_] = raises if raises is not None else []


class Attribute(Node):
    """One attribute of an interface or value type."""

    __slots__ = (
        "annotations", "doc", "get_raises", "get_raises_names", "name", "pos", "readonly",
        "set_raises", "set_raises_names", "type",
    )  # fmt: skip

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        type: TypeSpec,
        readonly: bool,
        get_raises_names: list[ScopedName],
        set_raises_names: list[ScopedName],
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
        get_raises: list[Exception_] | None = None,
        set_raises: list[Exception_] | None = None,
    ) -> None:
        self.name = name
        self.pos = pos
        self.type = type
        self.readonly = readonly
        self.get_raises_names = get_raises_names
        self.set_raises_names = set_raises_names
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc
        self.get_raises: list[Exception_] = get_raises if get_raises is not None else []
        self.set_raises: list[Exception_] = set_raises if set_raises is not None else []


class AttributeGroup(Node):
    """`attribute T a, b;` as parsed; the resolver turns each name into an `Attribute`."""

    __slots__ = (
        "annotations", "doc", "get_raises_names", "names", "readonly", "set_raises_names", "type",
    )  # fmt: skip

    def __init__(
        self,
        type: TypeSpec,
        readonly: bool,
        names: list[tuple[str, SourcePos]],
        get_raises_names: list[ScopedName],
        set_raises_names: list[ScopedName],
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
    ) -> None:
        self.type = type
        self.readonly = readonly
        self.names = names
        self.get_raises_names = get_raises_names
        self.set_raises_names = set_raises_names
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc


class Interface(Decl):
    """`[abstract|local] interface I [: bases] { exports };`"""

    __slots__ = (
        "abstract", "attributes", "base_names", "base_refs", "bases", "body", "local", "operations",
    )  # fmt: skip

    kind = "interface"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        abstract: bool = False,
        local: bool = False,
        base_names: list[ScopedName] | None = None,
        body: list[Definition] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.abstract = abstract
        self.local = local
        self.base_names: list[ScopedName] = base_names if base_names is not None else []
        self.body: list[Definition] = body if body is not None else []
        self.bases: list[Interface] = []
        # What each base name denotes, as written: the interface, or a typedef of it.
        self.base_refs: list[Decl] = []
        self.operations: list[Operation] = []
        self.attributes: list[Attribute] = []

    @property
    def is_interface(self) -> bool:
        return True


class Factory(Node):
    """A value type's `factory name(in ...)` initialiser."""

    __slots__ = ("annotations", "doc", "name", "params", "pos", "raises", "raises_names")

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        params: list[Param],
        raises_names: list[ScopedName],
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
    ) -> None:
        self.name = name
        self.pos = pos
        self.params = params
        self.raises_names = raises_names
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc
        self.raises: list[Exception_] = []


class StateMemberGroup(Node):
    """`public T a, b;` in a value type, as parsed."""

    __slots__ = ("annotations", "declarators", "doc", "pos", "public", "type")

    def __init__(
        self,
        public: bool,
        type: TypeSpec,
        declarators: list[tuple[str, SourcePos, list[Expr]]],
        pos: SourcePos,
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
    ) -> None:
        self.public = public
        self.type = type
        self.declarators = declarators
        self.pos = pos
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc


class ValueType(Decl):
    """A value type (concrete, abstract or custom)."""

    __slots__ = (
        "abstract", "attributes", "base_names", "base_refs", "bases", "body", "custom",
        "factories", "members", "operations", "supports", "supports_names", "supports_refs",
        "truncatable",
    )  # fmt: skip

    kind = "valuetype"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        abstract: bool = False,
        custom: bool = False,
        truncatable: bool = False,
        base_names: list[ScopedName] | None = None,
        supports_names: list[ScopedName] | None = None,
        body: list[Definition] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.abstract = abstract
        self.custom = custom
        self.truncatable = truncatable
        self.base_names: list[ScopedName] = base_names if base_names is not None else []
        self.supports_names: list[ScopedName] = supports_names if supports_names is not None else []
        self.body: list[Definition] = body if body is not None else []
        self.bases: list[ValueType] = []
        self.supports: list[Interface] = []
        # What each base and supported name denotes, as written (the type or a typedef of it).
        self.base_refs: list[Decl] = []
        self.supports_refs: list[Decl] = []
        self.members: list[Member] = []
        self.operations: list[Operation] = []
        self.attributes: list[Attribute] = []
        self.factories: list[Factory] = []


class ValueBox(Decl):
    """`valuetype V T;` (a boxed value)."""

    __slots__ = ("type",)

    kind = "valuebox"

    def __init__(self, name: str, pos: SourcePos, type: TypeSpec | None = None, **kw: Any) -> None:
        super().__init__(name, pos, **kw)
        self.type: TypeSpec = type if type is not None else BaseType("long")
