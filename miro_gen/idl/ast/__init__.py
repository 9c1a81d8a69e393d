"""The IDL abstract syntax tree, which the resolver completes into the resolved model.

The parser builds these nodes directly (no intermediate parse tree). The resolver then fills in
what needs scopes: scoped names, repository ids, references from names to declarations, and the
values of constant expressions, array bounds and union labels. Code generators and the AST JSON
read the resolved tree; nothing downstream re-parses or re-resolves.

The node classes are plain `__slots__` classes rather than dataclasses: a compiler run is short,
and generating forty dataclasses costs more start-up time than parsing a small file.

The nodes are in four modules, re-exported here (`from miro_gen.idl import ast`; `ast.Struct`):
`expressions` (names, constant expressions, annotations), `type_specs`, `declarations`
(modules and data types), `interfaces` (interfaces and value types).
"""

from __future__ import annotations

from miro_gen.idl.ast.declarations import AnnotationDecl as AnnotationDecl
from miro_gen.idl.ast.declarations import CaseBranch as CaseBranch
from miro_gen.idl.ast.declarations import Const as Const
from miro_gen.idl.ast.declarations import Decl as Decl
from miro_gen.idl.ast.declarations import Enum as Enum
from miro_gen.idl.ast.declarations import Enumerator as Enumerator
from miro_gen.idl.ast.declarations import Exception_ as Exception_
from miro_gen.idl.ast.declarations import Forward as Forward
from miro_gen.idl.ast.declarations import Member as Member
from miro_gen.idl.ast.declarations import Module as Module
from miro_gen.idl.ast.declarations import Native as Native
from miro_gen.idl.ast.declarations import Pragma as Pragma
from miro_gen.idl.ast.declarations import Struct as Struct
from miro_gen.idl.ast.declarations import Typedef as Typedef
from miro_gen.idl.ast.declarations import TypedefGroup as TypedefGroup
from miro_gen.idl.ast.declarations import TypeIdDcl as TypeIdDcl
from miro_gen.idl.ast.declarations import Union_ as Union_
from miro_gen.idl.ast.expressions import Annotation as Annotation
from miro_gen.idl.ast.expressions import BinaryOp as BinaryOp
from miro_gen.idl.ast.expressions import ConstValue as ConstValue
from miro_gen.idl.ast.expressions import EnumValue as EnumValue
from miro_gen.idl.ast.expressions import Expr as Expr
from miro_gen.idl.ast.expressions import Literal as Literal
from miro_gen.idl.ast.expressions import NameRef as NameRef
from miro_gen.idl.ast.expressions import Node as Node
from miro_gen.idl.ast.expressions import ScopedName as ScopedName
from miro_gen.idl.ast.expressions import UnaryOp as UnaryOp
from miro_gen.idl.ast.interfaces import Attribute as Attribute
from miro_gen.idl.ast.interfaces import AttributeGroup as AttributeGroup
from miro_gen.idl.ast.interfaces import Factory as Factory
from miro_gen.idl.ast.interfaces import Interface as Interface
from miro_gen.idl.ast.interfaces import Operation as Operation
from miro_gen.idl.ast.interfaces import Param as Param
from miro_gen.idl.ast.interfaces import StateMemberGroup as StateMemberGroup
from miro_gen.idl.ast.interfaces import ValueBox as ValueBox
from miro_gen.idl.ast.interfaces import ValueType as ValueType
from miro_gen.idl.ast.type_specs import BaseType as BaseType
from miro_gen.idl.ast.type_specs import FixedType as FixedType
from miro_gen.idl.ast.type_specs import MapType as MapType
from miro_gen.idl.ast.type_specs import NamedType as NamedType
from miro_gen.idl.ast.type_specs import SequenceType as SequenceType
from miro_gen.idl.ast.type_specs import StringType as StringType
from miro_gen.idl.ast.type_specs import TypeSpec as TypeSpec

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

    __slots__ = ("declarations", "definitions", "includes", "main_file", "ros2_hashes")

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
        # ROS 2 interfaces only: the RIHS01 type hash of each struct, by scoped name.
        self.ros2_hashes: dict[str, str] = {}
