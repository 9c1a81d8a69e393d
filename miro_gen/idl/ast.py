"""The IDL abstract syntax tree, which the resolver completes into the resolved model.

The parser builds these nodes directly (no intermediate parse tree). The resolver then fills in
what needs scopes: scoped names, repository ids, references from names to declarations, and the
values of constant expressions, array bounds and union labels. Code generators and the AST JSON
read the resolved tree; nothing downstream re-parses or re-resolves.

The node classes are plain `__slots__` classes rather than dataclasses: a compiler run is short,
and generating forty dataclasses costs more start-up time than parsing a small file.
"""

from __future__ import annotations

from decimal import Decimal
from typing import Any, Union

from miro_gen.diagnostics import SourcePos


class Node:
    """Base of all nodes: a readable `repr` from the slots."""

    __slots__ = ()

    def __repr__(self) -> str:
        names = [n for cls in reversed(type(self).__mro__) for n in getattr(cls, "__slots__", ())]
        inner = ", ".join(f"{n}={getattr(self, n)!r}" for n in names if n not in ("enum", "full"))
        return f"{type(self).__name__}({inner})"


# ---- names --------------------------------------------------------------------------------


class ScopedName(Node):
    """A name as written: `A::B` (relative) or `::A::B` (absolute)."""

    __slots__ = ("absolute", "parts", "pos")

    def __init__(self, parts: tuple[str, ...], absolute: bool, pos: SourcePos) -> None:
        self.parts = parts
        self.absolute = absolute
        self.pos = pos

    def __str__(self) -> str:
        return ("::" if self.absolute else "") + "::".join(self.parts)


# ---- expressions --------------------------------------------------------------------------

ConstValue = Union[int, float, str, bool, Decimal, "EnumValue"]


class EnumValue(Node):
    """The value of an enumerator: its enum, its name and its ordinal (hashable, immutable)."""

    __slots__ = ("enum", "name", "ordinal")

    def __init__(self, enum: Enum, name: str, ordinal: int) -> None:
        self.enum = enum
        self.name = name
        self.ordinal = ordinal

    @property
    def scoped_name(self) -> str:
        # Enumerators belong to the scope enclosing their enum (CORBA 3.0 section 3.11.2.4).
        return "::".join((*self.enum.scope_path[:-1], self.name))

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, EnumValue)
            and other.enum is self.enum
            and other.ordinal == self.ordinal
        )

    def __hash__(self) -> int:
        return hash((id(self.enum), self.ordinal))


class Literal(Node):
    """A literal; `kind` is int, float, fixed, char, wchar, string, wstring or bool."""

    __slots__ = ("kind", "pos", "value")

    def __init__(self, kind: str, value: ConstValue, pos: SourcePos) -> None:
        self.kind = kind
        self.value = value
        self.pos = pos


class NameRef(Node):
    """A constant or enumerator used in an expression."""

    __slots__ = ("name", "pos")

    def __init__(self, name: ScopedName, pos: SourcePos) -> None:
        self.name = name
        self.pos = pos


class UnaryOp(Node):
    """`-x`, `+x` or `~x`."""

    __slots__ = ("op", "operand", "pos")

    def __init__(self, op: str, operand: Expr, pos: SourcePos) -> None:
        self.op = op
        self.operand = operand
        self.pos = pos


class BinaryOp(Node):
    """`a OP b` with OP one of `| ^ & >> << + - * / %`."""

    __slots__ = ("left", "op", "pos", "right")

    def __init__(self, op: str, left: Expr, right: Expr, pos: SourcePos) -> None:
        self.op = op
        self.left = left
        self.right = right
        self.pos = pos


Expr = Literal | NameRef | UnaryOp | BinaryOp


# ---- annotations --------------------------------------------------------------------------


class Annotation(Node):
    """`@name` or `@name(args)`; one unnamed argument is stored under "value"."""

    __slots__ = ("args", "name", "params", "pos")

    def __init__(
        self,
        name: ScopedName,
        args: dict[str, Expr],
        pos: SourcePos,
        params: dict[str, ConstValue] | None = None,
    ) -> None:
        self.name = name
        self.args = args
        self.pos = pos
        self.params: dict[str, ConstValue] = params if params is not None else {}  # evaluated

    @property
    def short_name(self) -> str:
        return self.name.parts[-1]


# ---- types --------------------------------------------------------------------------------


class BaseType(Node):
    """A basic type, named by its IDL spelling (`long`, `unsigned long long`, `boolean`...)."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __str__(self) -> str:
        return self.name

    def __eq__(self, other: object) -> bool:
        return isinstance(other, BaseType) and other.name == self.name

    def __hash__(self) -> int:
        return hash(self.name)


class StringType(Node):
    """`string`, `wstring`, `string<N>`, `wstring<N>`."""

    __slots__ = ("bound", "bound_expr", "pos", "wide")

    def __init__(
        self, wide: bool, bound_expr: Expr | None, pos: SourcePos, bound: int | None = None
    ) -> None:
        self.wide = wide
        self.bound_expr = bound_expr
        self.pos = pos
        self.bound = bound

    def __str__(self) -> str:
        base = "wstring" if self.wide else "string"
        return f"{base}<{self.bound}>" if self.bound is not None else base


class SequenceType(Node):
    """`sequence<T>` or `sequence<T, N>`."""

    __slots__ = ("bound", "bound_expr", "element", "pos")

    def __init__(
        self, element: TypeSpec, bound_expr: Expr | None, pos: SourcePos, bound: int | None = None
    ) -> None:
        self.element = element
        self.bound_expr = bound_expr
        self.pos = pos
        self.bound = bound


class FixedType(Node):
    """`fixed<D, S>`, or the bare `fixed` of a constant declaration (no digits or scale)."""

    __slots__ = ("digits", "digits_expr", "pos", "scale", "scale_expr")

    def __init__(
        self,
        digits_expr: Expr | None,
        scale_expr: Expr | None,
        pos: SourcePos,
        digits: int | None = None,
        scale: int | None = None,
    ) -> None:
        self.digits_expr = digits_expr
        self.scale_expr = scale_expr
        self.pos = pos
        self.digits = digits
        self.scale = scale


class MapType(Node):
    """IDL 4 `map<K, V>` or `map<K, V, N>`."""

    __slots__ = ("bound", "bound_expr", "key", "pos", "value")

    def __init__(
        self,
        key: TypeSpec,
        value: TypeSpec,
        bound_expr: Expr | None,
        pos: SourcePos,
        bound: int | None = None,
    ) -> None:
        self.key = key
        self.value = value
        self.bound_expr = bound_expr
        self.pos = pos
        self.bound = bound


class NamedType(Node):
    """A reference to a declared type by name; `decl` is set by the resolver."""

    __slots__ = ("decl", "name")

    def __init__(self, name: ScopedName, decl: Decl | None = None) -> None:
        self.name = name
        self.decl = decl


TypeSpec = Union[
    BaseType, StringType, SequenceType, FixedType, MapType, NamedType, "Struct", "Union_", "Enum"
]


# ---- declarations -------------------------------------------------------------------------


_NO_PRAGMAS: list[Pragma] = []  # shared, never appended to


class Decl(Node):
    """A named declaration. `scope_path` and `repo_id` are set by the resolver."""

    __slots__ = (
        "annotations", "doc", "instance", "name", "pos", "pragmas", "repo_id", "scope_path",
    )  # fmt: skip

    kind = "decl"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        *,
        doc: str | None = None,
        annotations: list[Annotation] | None = None,
        scope_path: tuple[str, ...] = (),
        repo_id: str = "",
        instance: int = 0,
        pragmas: list[Pragma] | None = None,
    ) -> None:
        self.name = name
        self.pos = pos
        self.doc = doc
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.scope_path = scope_path
        self.repo_id = repo_id
        self.instance = instance  # preprocessor file instance, for #pragma prefix scoping
        # `#pragma` lines inside a struct, exception, union or enum body (OMG's ir.idl has them).
        self.pragmas: list[Pragma] = pragmas if pragmas is not None else _NO_PRAGMAS

    @property
    def scoped_name(self) -> str:
        return "::".join(self.scope_path)

    @property
    def resolved(self) -> Decl:
        """The declaration itself; for a forward declaration, the complete one once seen."""
        return self

    @property
    def is_interface(self) -> bool:
        """Whether values of this type are object references (an interface, or its forward
        declaration)."""
        return False


class Module(Decl):
    """`module M { ... };` (each opening of a module is its own node)."""

    __slots__ = ("definitions",)

    kind = "module"

    def __init__(
        self, name: str, pos: SourcePos, definitions: list[Definition] | None = None, **kw: Any
    ) -> None:
        super().__init__(name, pos, **kw)
        self.definitions: list[Definition] = definitions if definitions is not None else []


class Member(Node):
    """A struct, exception or value-type state member (one per declarator)."""

    __slots__ = ("annotations", "dims", "dims_expr", "doc", "name", "pos", "public", "type")

    def __init__(
        self,
        name: str,
        type: TypeSpec,
        dims_expr: list[Expr],
        pos: SourcePos,
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
        dims: list[int] | None = None,
        public: bool = True,
    ) -> None:
        self.name = name
        self.type = type
        self.dims_expr = dims_expr
        self.pos = pos
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc
        self.dims: list[int] = dims if dims is not None else []
        self.public = public  # value-type state members only


class Struct(Decl):
    """`struct S [: Base] { members };`"""

    __slots__ = ("base", "base_name", "members")

    kind = "struct"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        base_name: ScopedName | None = None,
        members: list[Member] | None = None,
        base: Struct | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.base_name = base_name
        self.members: list[Member] = members if members is not None else []
        self.base = base

    @property
    def all_members(self) -> list[Member]:
        """The members in encoding order: those of the IDL 4 base struct (and its bases) first."""
        chain: list[Struct] = []
        node: Struct | None = self
        while node is not None:
            chain.append(node)
            node = node.base
        return [m for s in reversed(chain) for m in s.members]


class CaseBranch(Node):
    """One branch of a union: its labels (None is `default`) and its declarator."""

    __slots__ = (
        "annotations", "dims", "dims_expr", "doc", "labels", "labels_expr", "name", "pos", "type",
    )  # fmt: skip

    def __init__(
        self,
        labels_expr: list[Expr | None],
        name: str,
        type: TypeSpec,
        dims_expr: list[Expr],
        pos: SourcePos,
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
        labels: list[ConstValue | None] | None = None,
        dims: list[int] | None = None,
    ) -> None:
        self.labels_expr = labels_expr
        self.name = name
        self.type = type
        self.dims_expr = dims_expr
        self.pos = pos
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc
        self.labels: list[ConstValue | None] = labels if labels is not None else []
        self.dims: list[int] = dims if dims is not None else []


class Union_(Decl):
    """`union U switch (T) { cases };`"""

    __slots__ = ("cases", "switch_annotations", "switch_type")

    kind = "union"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        switch_type: TypeSpec | None = None,
        cases: list[CaseBranch] | None = None,
        switch_annotations: list[Annotation] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.switch_type: TypeSpec = switch_type if switch_type is not None else BaseType("long")
        self.cases: list[CaseBranch] = cases if cases is not None else []
        self.switch_annotations: list[Annotation] = (
            switch_annotations if switch_annotations is not None else []
        )


class Enumerator(Decl):
    """An enumerator; it belongs to the scope that encloses its enum."""

    __slots__ = ("enum", "ordinal")

    kind = "enumerator"

    def __init__(
        self, name: str, pos: SourcePos, enum: Enum | None = None, ordinal: int = 0, **kw: Any
    ) -> None:
        super().__init__(name, pos, **kw)
        self.enum = enum
        self.ordinal = ordinal


class Enum(Decl):
    """`enum E { A, B };`"""

    __slots__ = ("enumerators",)

    kind = "enum"

    def __init__(
        self, name: str, pos: SourcePos, enumerators: list[Enumerator] | None = None, **kw: Any
    ) -> None:
        super().__init__(name, pos, **kw)
        self.enumerators: list[Enumerator] = enumerators if enumerators is not None else []


class Typedef(Decl):
    """One declarator of a typedef: `typedef T name[dims];`."""

    __slots__ = ("dims", "dims_expr", "type")

    kind = "typedef"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        type: TypeSpec | None = None,
        dims_expr: list[Expr] | None = None,
        dims: list[int] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.type: TypeSpec = type if type is not None else BaseType("long")
        self.dims_expr: list[Expr] = dims_expr if dims_expr is not None else []
        self.dims: list[int] = dims if dims is not None else []


class TypedefGroup(Node):
    """`typedef T a, b[2];` as parsed; the resolver turns each declarator into a `Typedef`."""

    __slots__ = ("annotations", "declarators", "doc", "instance", "pos", "type")

    def __init__(
        self,
        type: TypeSpec,
        declarators: list[tuple[str, SourcePos, list[Expr]]],
        pos: SourcePos,
        annotations: list[Annotation] | None = None,
        doc: str | None = None,
        instance: int = 0,
    ) -> None:
        self.type = type
        self.declarators = declarators
        self.pos = pos
        self.annotations: list[Annotation] = annotations if annotations is not None else []
        self.doc = doc
        self.instance = instance


class Const(Decl):
    """`const T name = expr;` with its evaluated `value`."""

    __slots__ = ("expr", "type", "value")

    kind = "const"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        type: TypeSpec | None = None,
        expr: Expr | None = None,
        value: ConstValue | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.type: TypeSpec = type if type is not None else BaseType("long")
        self.expr = expr
        self.value = value


class Exception_(Decl):
    """`exception E { members };`"""

    __slots__ = ("members",)

    kind = "exception"

    def __init__(
        self, name: str, pos: SourcePos, members: list[Member] | None = None, **kw: Any
    ) -> None:
        super().__init__(name, pos, **kw)
        self.members: list[Member] = members if members is not None else []

    @property
    def all_members(self) -> list[Member]:
        """The members in encoding order (exceptions have no bases)."""
        return self.members


class Native(Decl):
    """`native N;`"""

    __slots__ = ()

    kind = "native"


class Forward(Decl):
    """A forward declaration of an interface, struct, union or value type."""

    __slots__ = ("abstract", "full", "local", "of")

    kind = "forward"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        of: str = "interface",
        abstract: bool = False,
        local: bool = False,
        full: Decl | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.of = of  # interface, struct, union, valuetype
        self.abstract = abstract
        self.local = local
        self.full = full  # the complete declaration, once seen

    @property
    def resolved(self) -> Decl:
        return self.full if self.full is not None else self

    @property
    def is_interface(self) -> bool:
        return self.of == "interface"


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


class AnnotationDecl(Decl):
    """An IDL 4 `@annotation name { ... };` declaration (kept, not interpreted)."""

    __slots__ = ("members",)

    kind = "annotation"

    def __init__(
        self,
        name: str,
        pos: SourcePos,
        members: list[tuple[str, TypeSpec, Expr | None]] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(name, pos, **kw)
        self.members = members if members is not None else []


class Pragma(Node):
    """A `#pragma prefix|version|ID` line, in source order among the definitions."""

    __slots__ = ("instance", "pos", "text")

    def __init__(self, text: str, pos: SourcePos, instance: int) -> None:
        self.text = text
        self.pos = pos
        self.instance = instance


class TypeIdDcl(Node):
    """CORBA 3 `typeid Name "id";` or `typeprefix Name "prefix";`."""

    __slots__ = ("is_prefix", "name", "pos", "value")

    def __init__(self, is_prefix: bool, name: ScopedName, value: str, pos: SourcePos) -> None:
        self.is_prefix = is_prefix
        self.name = name
        self.value = value
        self.pos = pos


Definition = (
    Decl
    | TypedefGroup
    | AttributeGroup
    | Operation
    | StateMemberGroup
    | Factory
    | Pragma
    | TypeIdDcl
)


class Specification(Node):
    """A resolved translation unit: its main file, its top-level definitions in order, and every
    declaration (including nested ones and those of included files) in source order."""

    __slots__ = ("declarations", "definitions", "includes", "main_file")

    def __init__(
        self,
        main_file: str,
        definitions: list[Definition],
        declarations: list[Decl] | None = None,
        includes: dict[str, list[str]] | None = None,
    ) -> None:
        self.main_file = main_file
        self.definitions = definitions
        self.declarations: list[Decl] = declarations if declarations is not None else []
        self.includes: dict[str, list[str]] = includes if includes is not None else {}
