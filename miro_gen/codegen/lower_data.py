"""Lowering of data declarations into contexts: enums, structs, exceptions, unions, typedefs
and constants (interfaces are in `lower_interface.py`)."""

from __future__ import annotations

from decimal import Decimal
from typing import TypeVar

from miro_gen.codegen import names
from miro_gen.codegen.codec import CodecPlanner, Encoded, single_unpack
from miro_gen.codegen.contexts import (
    BranchContext,
    ConstContext,
    EnumContext,
    EnumeratorContext,
    ExceptionContext,
    FieldContext,
    ModuleContext,
    StructContext,
    TypedefContext,
    UnionContext,
)
from miro_gen.codegen.hints import TypeHints, enumerator_name
from miro_gen.codegen.schema import data_schema
from miro_gen.codegen.scope import Scope
from miro_gen.codegen.shapes import DATA_KINDS, Shape, Unsupported, member_shape, shape_of
from miro_gen.codegen.steps import (
    Assign,
    DecodeBranches,
    DecodeCase,
    DecodeStep,
    EncodeBranches,
    EncodeCase,
    EncodeStep,
)
from miro_gen.idl import ast
from miro_gen.runtime.datatypes import default_discriminator

XCDR2_ANNOTATIONS = {"appendable", "mutable", "optional", "external"}

Nested = list[tuple[str, str]]
Record = TypeVar("Record", StructContext, ExceptionContext)


class DataLowering:
    """Contexts of data declarations, written into the module contexts passed in."""

    def __init__(
        self, scope: Scope, hints: TypeHints, ros2_hashes: dict[str, str] | None = None
    ) -> None:
        self.scope = scope
        self.hints = hints
        self.ros2_hashes = ros2_hashes or {}  # RIHS01 type hashes of ROS 2 structs

    # ---- enums, typedefs, constants --------------------------------------------------------
    def enum(self, d: ast.Enum, m: ModuleContext, nested: bool) -> EnumContext:
        """An IntEnum; its enumerators are also module constants unless the enum is `nested`
        in a class (enumerators belong to the scope enclosing the enum)."""
        m.use("enum")
        if not nested and d.enumerators:
            m.use("typing")  # the module constants are `_t.Final`
        return EnumContext(
            name=self.scope.place(d).cls,
            scoped_name=d.scoped_name,
            doc=d.doc,
            enumerators=[
                EnumeratorContext(
                    m.ambiguous(enumerator_name(e.name), "E741"), e.ordinal, e.doc, not nested
                )
                for e in d.enumerators
            ],
        )

    def typedef(self, d: ast.Typedef, m: ModuleContext) -> TypedefContext:
        shape = shape_of(d.type, d.pos, d.dims)
        m.use("typing")
        target = self.hints.annotation(shape, m, use_alias=not d.dims)
        # A typedef of a class its module defines later (recursion through a forward
        # declaration) must be a string.
        inner = shape.innermost
        quoted = False
        if inner.kind in ("enum", *DATA_KINDS) and inner.decl is not None:
            place = self.scope.find(inner.decl.resolved)
            if place is not None and place.module == m.name:
                quoted = all(i.name != place.cls for i in m.items)
        cls = self.scope.place(d).cls
        return TypedefContext(cls, d.scoped_name, d.doc, target=target, quoted=quoted)

    def const(self, d: ast.Const, m: ModuleContext) -> ConstContext:
        m.use("typing")
        v = d.value
        if isinstance(v, ast.EnumValue):
            value = self.hints.enumerator(v.enum, v.name, m)
        elif isinstance(v, bool):
            value = "True" if v else "False"
        elif isinstance(v, Decimal):
            m.use("decimal")
            value = f'_decimal.Decimal("{v}")'
        else:
            value = repr(v)
        return ConstContext(self.scope.place(d).cls, d.scoped_name, d.doc, value=value)

    # ---- structs and exceptions ------------------------------------------------------------
    def struct(self, d: ast.Struct, m: ModuleContext, nested: Nested) -> StructContext:
        m.use("dc", "cdr")
        members = d.all_members
        _check_xcdr1(d, members)
        struct = self._record(StructContext, d, members, names.STRUCT_ATTRIBUTES, m, nested)
        struct.bases = [self.scope.ref(d.base, m)] if d.base is not None else []
        ros2_hash = self.ros2_hashes.get(d.scoped_name)
        if ros2_hash is not None:
            struct.ros2_type = "/".join(d.scope_path)
            struct.ros2_type_hash = ros2_hash
        return struct

    def exception(self, d: ast.Exception_, m: ModuleContext, nested: Nested) -> ExceptionContext:
        m.use("dc", "cdr", "exc")
        _check_xcdr1(d, d.members)
        reserved = names.EXCEPTION_ATTRIBUTES
        return self._record(ExceptionContext, d, d.members, reserved, m, nested)

    def _record(
        self,
        kind: type[Record],
        d: ast.Struct | ast.Exception_,
        members: list[ast.Member],
        reserved: frozenset[str],
        m: ModuleContext,
        nested: Nested,
    ) -> Record:
        """A struct or exception: its own members as fields; `members` (with the base
        struct's) encoded in order."""
        fields = self._fields(d.members, reserved, m, ros2=d.scoped_name in self.ros2_hashes)
        encode, decode, args = self._codec(d, members, reserved, m)
        return kind(
            name=self.scope.place(d).cls,
            scoped_name=d.scoped_name,
            doc=d.doc,
            repo_id=d.repo_id,
            schema=data_schema(d),
            nested=nested,
            encode=encode,
            decode=decode,
            construct_args=args,
            fields=fields,
        )

    def _fields(
        self,
        members: list[ast.Member],
        reserved: frozenset[str],
        m: ModuleContext,
        ros2: bool = False,
    ) -> list[FieldContext]:
        """The dataclass fields of `members`; a ROS 2 type's (`ros2`) take their `@default`
        values, as rosidl_generator_py's classes do (other IDL keeps `@default` an annotation)."""
        out = []
        for member in members:
            shape = member_shape(member)
            annotation = self.hints.annotation(shape, m, use_alias=not member.dims)
            name = m.ambiguous(names.py_name(member.name, reserved), "E741")
            given = _ros2_default(member) if ros2 else None
            default = (
                self.hints.default(shape, m) if given is None else self.hints.given(shape, given, m)
            )
            out.append(FieldContext(name, annotation, default.value, default.factory, member.doc))
        return out

    def _codec(
        self,
        d: ast.Struct | ast.Exception_,
        members: list[ast.Member],
        reserved: frozenset[str],
        m: ModuleContext,
    ) -> tuple[list[EncodeStep], list[DecodeStep], list[str]]:
        """The encoder's and the decoder's steps, and the decoder's constructor arguments."""
        planner = CodecPlanner(self.scope, self.hints, m)
        entries: list[Encoded] = [
            (
                member_shape(member),
                f"_v.{names.py_name(member.name, reserved)}",
                f"{d.scoped_name}.{member.name}",
            )
            for member in members
        ]
        encode = planner.encode_members(entries)
        decode, values = planner.decode_members([(s, w) for s, _, w in entries])
        tup = single_unpack(decode, values)
        return encode, decode, [f"*{tup}"] if tup else values

    # ---- unions ----------------------------------------------------------------------------
    def union(self, d: ast.Union_, m: ModuleContext, nested: Nested) -> UnionContext:
        m.use("cdr", "typing")
        _check_xcdr1(d, [])
        cls = self.scope.place(d).cls
        disc = shape_of(d.switch_type, d.pos)
        branches: list[BranchContext] = []
        used: set[object] = set()
        default_branch = None
        for case in d.cases:
            name = m.ambiguous(names.py_name(case.name, names.STRUCT_ATTRIBUTES), "E743")
            shape = member_shape(case)
            values = [v for v in case.labels if v is not None]
            used.update(v.ordinal if isinstance(v, ast.EnumValue) else v for v in values)
            if None in case.labels:
                default_branch = name
            branches.append(
                BranchContext(
                    name=name,
                    annotation=self.hints.annotation(shape, m, use_alias=not case.dims),
                    labels=[self._label(v, m) for v in values],
                    zero=self.hints.default(shape, m).zero,
                    doc=case.doc,
                )
            )
        # The discriminator the default branch gets, chosen as Cyclone DDS chooses it.
        default_d = "None"
        if default_branch is not None:
            if disc.kind == "enum":
                enumerators = disc.enum.enumerators
                i = default_discriminator("enum", used, len(enumerators))
                if i < len(enumerators):
                    default_d = self.hints.enumerator(disc.enum, enumerators[i].name, m)
            else:
                assert disc.prim is not None
                default_d = repr(default_discriminator(disc.prim.idl, used))
        discriminator = self.hints.annotation(disc, m)
        encode, decode = self._union_codec(d, disc, branches, m)
        return UnionContext(
            name=cls,
            scoped_name=d.scoped_name,
            doc=d.doc,
            repo_id=d.repo_id,
            schema=data_schema(d),
            nested=nested,
            encode=encode,
            decode=decode,
            construct_args=["_d", "_x"],
            branches=branches,
            discriminator=discriminator,
            default_branch=default_branch,
            default_discriminator=default_d,
        )

    def _union_codec(
        self, d: ast.Union_, disc: Shape, branches: list[BranchContext], m: ModuleContext
    ) -> tuple[list[EncodeStep], list[DecodeStep]]:
        planner = CodecPlanner(self.scope, self.hints, m)
        what = d.scoped_name
        encode = planner.encode_members([(disc, "_v._d", f"{what} discriminator")])
        decode, (disc_value,) = planner.decode_members([(disc, f"{what} discriminator")])
        enc_cases: list[EncodeCase] = []
        dec_cases: list[DecodeCase] = []
        default_enc: list[EncodeStep] = []
        default_dec: list[DecodeStep] = []
        for case, branch in zip(d.cases, branches, strict=True):
            shape = member_shape(case)
            e_steps = planner.encode_value(shape, "_v._v", f"{what}.{case.name}")
            d_steps = planner.decode_value(shape, "_x", f"{what}.{case.name}")
            if None in case.labels:
                default_enc, default_dec = e_steps, d_steps
            if branch.labels:
                enc_cases.append(EncodeCase(branch.labels, e_steps))
                dec_cases.append(DecodeCase(branch.labels, d_steps))
        encode.append(EncodeBranches(expr="_v._d", cases=enc_cases, default=default_enc, what=what))
        decode.append(Assign(var="_d", expr=disc_value))
        decode.append(DecodeBranches(cases=dec_cases, default=default_dec))
        return encode, decode

    def _label(self, v: ast.ConstValue, m: ModuleContext) -> str:
        if isinstance(v, ast.EnumValue):
            return self.hints.enumerator(v.enum, v.name, m)
        return repr(v)


def _check_xcdr1(d: ast.Struct | ast.Exception_ | ast.Union_, members: list[ast.Member]) -> None:
    """Refuse the extensibility annotations of XCDR2, which the codec does not implement."""
    for a in d.annotations:
        n = a.short_name
        value = a.params.get("value")
        if n in ("appendable", "mutable") or (
            n == "extensibility" and str(value).upper() in ("APPENDABLE", "MUTABLE")
        ):
            raise Unsupported(
                a.pos,
                f"'{d.scoped_name}' is @{n if n != 'extensibility' else str(value).lower()}: "
                "XCDR2 encoding is not supported yet; only final (XCDR1) types",
            )
    for member in members:
        for a in member.annotations:
            if a.short_name in XCDR2_ANNOTATIONS and a.params.get("value", True) is not False:
                raise Unsupported(
                    a.pos,
                    f"member '{member.name}' of '{d.scoped_name}' is @{a.short_name}: "
                    "XCDR2 encoding is not supported yet",
                )


def _ros2_default(member: ast.Member) -> ast.ConstValue | None:
    """The value of a member's `@default` annotation (ROS 2 interfaces), if it has one."""
    for a in member.annotations:
        if a.short_name == "default":
            return a.params.get("value")
    return None
