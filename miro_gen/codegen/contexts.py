"""The Python back end's context model: one small class per generated kind.

Lowering (`lower.py`, `lower_data.py`, `lower_interface.py`) turns each IDL declaration into
one of these, with every Python name, annotation, default value, docstring fallback and codec
step computed; each class names its template (`template`), and the templates in
`templates/idl/` only lay the fields out. A `ModuleContext` holds the items of one generated
module in dependency order, with what the module imports and the `struct.Struct`s and
attribute getters its codecs share; a `PackageContext` is a package's `__init__`.

To add a feature to the generated code: add a field (or a property) here, fill it in the
lowering of its kind, and use it in that kind's template.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

from miro_gen.codegen import names
from miro_gen.codegen.steps import DecodeStep, EncodeStep

# The standard-library modules generated code may use, by the key lowering records in
# `ModuleContext.uses`, in the order isort puts them.
STDLIB_IMPORTS = {
    "abc": "import abc as _abc",
    "dc": "import dataclasses as _dc",
    "decimal": "import decimal as _decimal",
    "enum": "import enum as _enum",
    "operator": "import operator as _operator",
    "typing": "import typing as _t",
}
# The miro_gen modules generated code may use, and their aliases.
RUNTIME_IMPORTS = {
    "exc": ("miro_gen.exceptions", "_exc"),
    "arrays": ("miro_gen.runtime.arrays", "_arrays"),
    "cdr": ("miro_gen.runtime.cdr", "_cdr"),
    "rpc": ("miro_gen.runtime.rpc", "_rpc"),
}


# ---- items of a module -----------------------------------------------------------------------


def schema_lines(schema: str) -> list[str]:
    """A schema as lines that keep their newline (one string literal each)."""
    return [line + "\n" for line in schema.split("\n")[:-1]]


@dataclass
class Item:
    """A generated declaration: a class, an alias or a constant at module level."""

    template: ClassVar[str]
    idl_kind: ClassVar[str] = ""  # the IDL keyword, for the docstring of undocumented types

    name: str  # the module-level Python name
    scoped_name: str  # the IDL name, Miro::Example
    doc: str | None

    @property
    def fallback_doc(self) -> str:
        """The docstring when the IDL has no doc comment."""
        return f"{self.idl_kind} {self.scoped_name}"


@dataclass
class EnumeratorContext:
    name: str
    value: int
    doc: str | None
    module_constant: bool  # also a module constant: the enum is not nested in a class


@dataclass
class EnumContext(Item):
    """`class E(enum.IntEnum)`, its ordinal tables, and its enumerators as module constants."""

    template = "idl/enum.py.j2"
    idl_kind = "enum"

    enumerators: list[EnumeratorContext]


@dataclass
class TypedefContext(Item):
    """`A: TypeAlias = T`; `quoted` when T is a class defined later in the module."""

    template = "idl/typedef.py.j2"

    target: str
    quoted: bool


@dataclass
class ConstContext(Item):
    """`X: Final = value`."""

    template = "idl/const.py.j2"

    value: str


@dataclass
class FieldContext:
    """A dataclass field: `name: annotation = value`, or `= _dc.field(default_factory=...)`."""

    name: str
    annotation: str
    value: str  # the default value, or "" when `factory` makes it
    factory: str  # a zero-argument callable making the default, or ""
    doc: str | None


@dataclass
class DataTypeContext(Item):
    """What structs, exceptions and unions share: type identity, data schema and codec."""

    repo_id: str
    schema: str  # the data schema (see schema.py)
    nested: list[tuple[str, str]]  # class attributes naming nested declarations
    encode: list[EncodeStep]
    decode: list[DecodeStep]
    construct_args: list[str]  # what the decoder passes to the class

    @cached_property
    def type_hash(self) -> str:
        return hashlib.sha256(self.schema.encode("utf-8")).hexdigest()

    @property
    def schema_lines(self) -> list[str]:
        return schema_lines(self.schema)


@dataclass
class RecordContext(DataTypeContext):
    """A data type with dataclass fields: a struct or an exception."""

    fields: list[FieldContext]


@dataclass
class StructContext(RecordContext):
    """`@dataclass(slots=True) class S` with its codec functions `_enc_S`, `_dec_S`."""

    template = "idl/struct.py.j2"
    idl_kind = "struct"

    bases: list[str] = field(default_factory=list)  # the base struct, if any
    # ROS 2 interfaces only (miro-idl --ros2, .msg/.srv/.action): the ROS 2 type name
    # (`std_msgs/msg/Header`) and its RIHS01 type hash; "" otherwise.
    ros2_type: str = ""
    ros2_type_hash: str = ""


@dataclass
class ExceptionContext(RecordContext):
    """`class E(UserException)` dataclass with its codec functions."""

    template = "idl/exception.py.j2"
    idl_kind = "exception"


@dataclass
class BranchContext:
    """One branch of a union: a property, its labels and the zero value it starts with."""

    name: str
    annotation: str
    labels: list[str]  # Python expressions of its case labels (none for a default-only branch)
    zero: str  # a zero-argument callable making the branch's default value
    doc: str | None

    @property
    def fallback_doc(self) -> str:
        return f"Branch {self.name}{'' if self.labels else ' (default)'}."


@dataclass
class UnionContext(DataTypeContext):
    """A subclass of `IdlUnion` with one property per branch and its codec functions."""

    template = "idl/union.py.j2"
    idl_kind = "union"

    branches: list[BranchContext]
    discriminator: str  # annotation of `_d`
    default_branch: str | None  # the branch `default:` selects
    default_discriminator: str  # the discriminator it gets, as Cyclone DDS chooses it


@dataclass
class ParamContext:
    name: str
    annotation: str
    mode: str  # in, out, inout

    @property
    def declaration(self) -> str:
        return f"{self.name}: {self.annotation}"


@dataclass
class OperationContext:
    """One operation (or attribute accessor) of a stub or a skeleton, with its four codecs."""

    name: str  # Python method name
    wire: str  # operation name on the wire
    doc: str | None
    oneway: bool
    params: list[ParamContext]
    returns: str  # annotation of what the Python method returns
    results: list[str]  # variables of the returned values, in order (result first)
    encode_in: list[EncodeStep]
    decode_in: list[DecodeStep]
    encode_out: list[EncodeStep]
    decode_out: list[DecodeStep]
    raises: list[str]  # exception classes the stub raises
    what: str  # Miro::Example::getData, for error messages

    @property
    def inputs(self) -> list[ParamContext]:
        """The parameters the Python method takes (`in` and `inout`)."""
        return [p for p in self.params if p.mode != "out"]

    @property
    def arguments(self) -> str:
        """The skeleton's call of the servant method: its arguments."""
        return ", ".join(p.name for p in self.inputs)

    @property
    def raises_tuple(self) -> str:
        if len(self.raises) == 1:
            return f"({self.raises[0]},)"
        return f"({', '.join(self.raises)})"

    @property
    def many_results(self) -> bool:
        return len(self.results) > 1


@dataclass
class InterfaceContext(Item):
    repo_id: str
    bases: list[str]
    operations: list[OperationContext]
    schema: str  # the interface schema (interface_schema.py); "" when it has none

    @cached_property
    def interface_hash(self) -> str:
        return hashlib.sha256(self.schema.encode("utf-8")).hexdigest() if self.schema else ""

    @property
    def schema_lines(self) -> list[str]:
        return schema_lines(self.schema)


@dataclass
class StubContext(InterfaceContext):
    """The client stub `Miro.I`: one method per operation, calling through the invoker."""

    template = "idl/stub.py.j2"

    nested: list[tuple[str, str]]

    @property
    def fallback_doc(self) -> str:
        return f"Client stub of interface {self.scoped_name}"


@dataclass
class SkeletonContext(InterfaceContext):
    """The skeleton `Miro__POA.I`: abstract methods and the dispatch table of a servant."""

    template = "idl/skeleton.py.j2"

    @property
    def fallback_doc(self) -> str:
        return (
            f"Skeleton of interface {self.scoped_name}: subclass it and implement the operations."
        )

    @property
    def inherited_dispatch(self) -> list[str]:
        """The base skeletons whose dispatch tables this one extends."""
        return [b for b in self.bases if b != "_rpc.Servant"]


# ---- modules and packages ----------------------------------------------------------------


@dataclass
class StructCodec:
    """A module-level `struct.Struct` pair (`_S3`) and its bound pack/unpack (`_P3`, `_U3`)."""

    var: str
    format: str

    @property
    def number(self) -> str:
        return self.var[2:]


@dataclass
class ModuleContext:
    """One generated module (`Miro/Example_idl.py` or `Miro__POA/Example_idl.py`).

    Lowering records into it what its items need: imports of other generated modules
    (`reference`), runtime and standard modules (`use`), shared codec structs and getters,
    and the ruff rules the module must exempt itself from.
    """

    package: str
    stem: str
    source: str  # the IDL file, as the header names it
    idl_module: str  # Miro::Sub, or "" for the global scope
    poa: bool = False
    items: list[Item] = field(default_factory=list)
    imports: dict[str, str] = field(default_factory=dict)  # module -> alias
    structs: dict[str, str] = field(default_factory=dict)  # format -> variable
    getters: dict[str, tuple[str, ...]] = field(default_factory=dict)  # variable -> attributes
    exports: list[str] = field(default_factory=list)
    uses: set[str] = field(default_factory=set)  # keys of STDLIB_IMPORTS and RUNTIME_IMPORTS
    noqa: set[str] = field(default_factory=set)  # ruff rules the whole module is exempt from

    # ---- recording -------------------------------------------------------------------------
    def use(self, *keys: str) -> None:
        self.uses.update(keys)

    def reference(self, module: str, cls: str) -> str:
        """The expression for class `cls` of generated module `module`, imported if need be."""
        if module == self.name:
            return cls
        alias = self.imports.get(module)
        if alias is None:
            alias = self.imports[module] = names.module_alias(module)
        return f"{alias}.{cls}"

    def struct_codec(self, fmt: str) -> str:
        """The number of the module's Struct pair for format `fmt` (made on first use)."""
        var = self.structs.get(fmt)
        if var is None:
            var = f"_S{len(self.structs)}"
            self.structs[fmt] = var
        return var[2:]

    def getter(self, var: str, attributes: tuple[str, ...]) -> str:
        self.getters[var] = attributes
        self.use("operator")
        return var

    def ambiguous(self, name: str, code: str) -> str:
        """Note a name pycodestyle calls ambiguous (l, O, I): the module exempts itself from that
        rule (E741 variables, E742 classes, E743 functions) rather than rename IDL names."""
        if name in ("l", "O", "I"):
            self.noqa.add(code)
        return name

    def add(self, item: Item, code: str) -> None:
        """Append a declaration (exported); `code` is the rule an ambiguous name breaks."""
        self.ambiguous(item.name, code)
        self.items.append(item)
        self.exports.append(item.name)

    # ---- what the templates and the package read ----------------------------------------
    @cached_property
    def name(self) -> str:
        return f"{self.package}.{self.stem}"

    @property
    def path(self) -> str:
        return "/".join(self.package.split(".")) + f"/{self.stem}.py"

    @property
    def summary(self) -> str:
        """The module docstring."""
        scope = self.idl_module or "(global scope)"
        if self.poa:
            return f"Skeletons (servant base classes) of IDL module {scope}, from {self.source}."
        return f"IDL module {scope}: the declarations of {self.source}."

    @property
    def sorted_exports(self) -> list[str]:
        """`__all__` in the order ruff's RUF022 wants: constants, classes, then the rest."""
        return sorted(self.exports, key=isort_key)

    @property
    def struct_codecs(self) -> list[StructCodec]:
        return [StructCodec(var, fmt) for fmt, var in sorted(self.structs.items(), key=_second)]

    @property
    def sorted_getters(self) -> list[tuple[str, tuple[str, ...]]]:
        return sorted(self.getters.items(), key=_lower_first)

    @property
    def type_hashes(self) -> dict[str, str]:
        """type hash -> class name, of the data types this module defines."""
        return {i.type_hash: i.name for i in self.items if isinstance(i, DataTypeContext)}

    @property
    def import_blocks(self) -> list[list[str]]:
        """Imports in isort's sections for this layout: standard library, other generated
        top-level packages (third party), then this module's own package with miro_gen (first
        party); each sorted as isort sorts (case-insensitively)."""
        own = self.package.split(".")[0]
        third = {m: a for m, a in self.imports.items() if m.split(".")[0] != own}
        first = {m: a for m, a in self.imports.items() if m.split(".")[0] == own}
        first.update(dict(RUNTIME_IMPORTS[u] for u in self.uses if u in RUNTIME_IMPORTS))
        blocks = [[line for use, line in STDLIB_IMPORTS.items() if use in self.uses]]
        for section in (third, first):
            blocks.append(
                [f"import {m} as {a}" for m, a in sorted(section.items(), key=_module_key)]
            )
        return [b for b in blocks if b]


@dataclass
class PackageContext:
    """A package `__init__` that imports its modules' names lazily (see its template)."""

    package: str
    modules: list[str]  # its *_idl modules, full names
    subpackages: list[str]  # names of its generated subpackages
    exports: dict[str, str]  # name -> the module defining it
    type_hashes: dict[str, str]  # type hash -> class name

    @property
    def path(self) -> str:
        return self.package.replace(".", "/") + "/__init__.py"

    @property
    def summary(self) -> str:
        top = self.package.split(".")[0]
        if top == names.GLOBAL_PACKAGE:
            return "IDL module (global scope)."
        idl_name = "::".join(self.package.split("."))
        if top.endswith(names.POA_SUFFIX):  # also _GlobalIDL__POA, named as a module
            return f"Skeletons of IDL module {idl_name.replace(names.POA_SUFFIX, '')}."
        return f"IDL module {idl_name}."

    @property
    def noqa(self) -> list[str]:
        """Ruff rules the `__init__` is exempt from: its names come from star imports (for type
        checkers only)."""
        return ["F403", "F405"] if self.modules else []

    @property
    def sorted_exports(self) -> list[tuple[str, str]]:
        return sorted(self.exports.items())

    @property
    def sorted_hashes(self) -> list[tuple[str, str]]:
        return sorted((h, n) for h, n in self.type_hashes.items() if n in self.exports)

    @property
    def submodules(self) -> list[str]:
        """The names `__getattr__` imports as submodules: the modules' stems and subpackages."""
        return sorted({m.rsplit(".", 1)[1] for m in self.modules} | set(self.subpackages))

    @property
    def public(self) -> list[str]:
        return sorted({*self.exports, *self.subpackages}, key=isort_key)


def _second(item: tuple[str, str]) -> str:
    return item[1]


def _lower_first(item: tuple[str, tuple[str, ...]]) -> str:
    return item[0].lower()  # as Jinja's dictsort sorted them


def _module_key(item: tuple[str, str]) -> list[int | str]:
    return _natural(item[0].lower())


def _natural(text: str) -> list[int | str]:
    return [int(p) if p.isdigit() else p for p in _DIGITS(text)]


_DIGITS = re.compile(r"(\d+)").split


def isort_key(name: str) -> tuple[int, list[int | str]]:
    """isort's order: CONSTANTS, Classes, then the rest; numbers in names compared as numbers."""
    if len(name) > 1 and name.isupper():
        kind = 0
    elif name[:1].isupper() or (name[:1] == "_" and name[1:2].isupper()):
        kind = 1
    else:
        kind = 2
    return kind, _natural(name)
