"""Declarations of modules and data types (structs, unions, enums, typedefs, constants,
exceptions, natives, forward declarations), with the questions asked of them (`resolved`,
`all_members`, `is_interface`); IDL 4 annotation declarations; `#pragma` and `typeid` lines."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from miro_gen.diagnostics import SourcePos
from miro_gen.idl.ast.expressions import Annotation, ConstValue, Expr, Node, ScopedName
from miro_gen.idl.ast.type_specs import BaseType, TypeSpec

if TYPE_CHECKING:
    from miro_gen.idl.ast import Definition


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
