"""The compile-time model of makeParams files: what `config_global`, `config_group`,
`config_item` and `config_parameter` say, with source positions, before any type is resolved."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from miro_gen.diagnostics import SourcePos


@dataclass
class ParamDecl:
    """A `config_parameter`."""

    name: str  # as written (the run-time name is it with the first letter upper-cased)
    type: str  # the C++ spelling
    pos: SourcePos
    default: str | None = None
    measure: str | None = None
    values: list[str] | None = None  # Enumeration / EnumerationMultiple choices
    static_const: bool = False
    inherited: bool = False
    doc: str | None = None

    @property
    def xml_name(self) -> str:
        return self.name[:1].upper() + self.name[1:]

    @property
    def attr(self) -> str:
        """makeParams' member name: the first letter lower-cased (`static_const` ones are
        upper-cased whole: `MAX_SPEED`)."""
        if self.static_const:
            return self.name.upper()
        return self.name[:1].lower() + self.name[1:]


@dataclass
class Constructor:
    """A `<constructor>` block: C++-like statements, compiled later."""

    text: str
    pos: SourcePos  # where the text starts


@dataclass
class ItemDecl:
    """A `config_item`: one parameter class (`<name>Parameters`).

    `final="false"` marks an abstract class (makeParams' editors offer only final ones); a
    `dummy` item is declared for the tools and written by hand (no class is generated); an
    `extern` item is a type defined elsewhere whose run-time layout is listed here."""

    name: str
    pos: SourcePos
    file: ParamsFile
    namespace: str = ""  # where it is declared: the namespace globals read so far
    parent: str | None = None
    final: bool = True
    dummy: bool = False
    extern: bool = False
    instance: bool = False
    group: str | None = None  # the config_group: the run-time section
    params: list[ParamDecl] = field(default_factory=list)
    # `<constructor>` blocks, run one after the other (makeParams appended them)
    constructors: list[Constructor] = field(default_factory=list)
    doc: str | None = None

    @property
    def class_name(self) -> str:
        """makeParams' naming; a `dummy` item names an existing (IDL) type as it is."""
        return self.name if self.dummy else f"{self.name}Parameters"

    @property
    def scoped_name(self) -> str:
        """The C++ name: a generated class lives in the file's namespace; a dummy item names
        a type where it is declared (`ACE_TTY_IO::Serial_Params` before any namespace)."""
        ns = self.namespace if self.dummy else self.file.namespace
        return f"{ns}::{self.class_name}" if ns else self.class_name

    @property
    def hand_written_name(self) -> str:
        """The class a dummy item stands for as a parent (makeParams appends `Parameters`)."""
        return self.class_name.rsplit("::", 1)[-1] + (
            "" if self.class_name.endswith("Parameters") else "Parameters"
        )


@dataclass
class Include:
    value: str
    pos: SourcePos
    kind: str  # "include", "Include" or "src_Include"
    params_file: Path | None = None  # a compile-time file it stands for
    idl_file: Path | None = None  # an IDL file it stands for, when found
    idl_stem: str | None = None  # `ScanDescription` for `idl/ScanDescriptionC.h`


@dataclass
class ParamsFile:
    """One compile-time file."""

    path: Path
    display: str  # how messages and generated headers name it
    namespace: str = ""
    includes: list[Include] = field(default_factory=list)
    forwards: list[str] = field(default_factory=list)
    items: list[ItemDecl] = field(default_factory=list)
    groups: list[str] = field(default_factory=list)
    helpers: dict[str, str] = field(default_factory=dict)  # C++ type -> Python helper module
    helper_pos: dict[str, SourcePos] = field(default_factory=dict)
    # dummy item (scoped C++ name) -> "module" or "module:Class" of its hand-written class
    python_classes: dict[str, str] = field(default_factory=dict)

    def pos(self, line: int | None, col: int = 0) -> SourcePos:
        return SourcePos(self.display, line or 0, col)
