"""What generated parameter modules import: the base class `Config`, struct layouts and errors.

A generated class lists its run-time parameters in `_xml_fields` (XML name, attribute, codec,
measure); `Config` reads and writes them (`from_xml` / `<<=`, `to_xml` / `>>=`) and prints them
(`str()`), as makeParams' generated `operator<<=`, `operator>>=` and `operator<<` did. IDL structs
described by a `dummy` item get a `Layout` instead: the same reader and writer for a dataclass.
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import threading
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, Self, TypeVar

import pydantic

from miro_gen.diagnostics import Diagnostic
from miro_gen.exceptions import ActionableError
from miro_gen.params.runtime import codecs, values
from miro_gen.params.runtime.codecs import (
    ANGLE,
    BOOL,
    FAIL,
    INT,
    TIME,
    UINT,
    Codec,
    Enum,
    Problems,
    Vector,
)
from miro_gen.params.runtime.lazy import load_secrets

if TYPE_CHECKING:
    from lxml import etree  # imported where XML is made or parsed: a service without a
    # parameter document starts without lxml

T = TypeVar("T")


class ParamsError(ActionableError):
    """A run-time document that does not fit the parameter classes; lists every problem as
    `path:line: error: message`. The parameters it was read into are left as they were."""

    def __init__(self, diagnostics: list[Diagnostic]) -> None:
        self.diagnostics = diagnostics
        super().__init__("\n".join(str(d) for d in diagnostics))


class XmlField(NamedTuple):
    """One run-time parameter of a class: its XML name (first letter upper-case), the Python
    attribute (first letter lower-case), its codec and its unit."""

    xml: str
    attr: str
    codec: Codec
    measure: str | None = None


class Layout:
    """The run-time parameters of a struct type: a `Config` subclass or an IDL dataclass."""

    def __init__(
        self, cls: type[Any], fields: Iterable[XmlField], constants: Iterable[str] = ()
    ) -> None:
        self.cls = cls
        self.fields = tuple(fields)
        self.constants = frozenset(constants)
        self.index: dict[str, XmlField] = {}
        for f in self.fields:  # the run-time name, and makeParams' member name
            self.index[f.xml] = f
            self.index[f.xml[:1].lower() + f.xml[1:]] = f
        self.is_config = isinstance(cls, type) and issubclass(cls, Config)

    def replace(self, current: Any, updates: dict[str, Any]) -> Any:
        if not updates:
            return current
        if self.is_config:
            return current.model_copy(update=updates)
        return dataclasses.replace(current, **updates)


_LAYOUTS: dict[type[Any], Layout] = {}


def layout_of(cls: type[Any]) -> Layout:
    """A `Config` subclass's parameters, its parents' first (an `inherited` parameter keeps its
    parent's place and takes its own default)."""
    layout = _LAYOUTS.get(cls)
    if layout is None:
        fields: dict[str, XmlField] = {}
        constants: set[str] = set()
        for klass in reversed(cls.__mro__):
            for f in klass.__dict__.get("_xml_fields", ()):
                fields[f.attr] = f
            constants.update(klass.__dict__.get("_xml_constants", ()))
        layout = _LAYOUTS[cls] = Layout(cls, fields.values(), constants)
    return layout


class Struct(Codec):
    """A nested parameter structure: `<parameter name="X">` with named children. The target is
    a class, a layout, or a function returning one (a class defined further down its module:
    recursive types)."""

    def __init__(
        self,
        target: type[Any] | Layout | Callable[[], type[Any] | Layout],
        label: str | None = None,
    ) -> None:
        self._target = target
        self._layout: Layout | None = target if isinstance(target, Layout) else None
        self.label = label or ""

    @property
    def layout(self) -> Layout:
        if self._layout is None:
            target = self._target
            if not isinstance(target, type) and callable(target):
                target = target()
            self._layout = target if isinstance(target, Layout) else layout_of(target)
        return self._layout

    @property
    def type_name(self) -> str:
        return self.label or self.layout.cls.__name__

    def default(self) -> Any:
        return self.layout.cls()

    def read(self, elem: etree._Element, current: Any, where: str, probs: Problems) -> Any:
        layout = self.layout
        if elem.get("value") is not None:
            probs.error(
                elem,
                f"{where}: a {self.type_name} is a structure: give its parameters as nested "
                '<parameter name="..."/>, not value=',
            )
            return FAIL
        updates: dict[str, Any] = {}
        seen: dict[str, int] = {}
        failed = False
        for child in codecs.children(elem, where, probs):
            name = child.get("name")
            if name is None:
                probs.error(child, f"{where}: a parameter of {self.type_name} needs a name=")
                failed = True
                continue
            f = layout.index.get(name)
            if f is None:
                failed = True
                if name.upper() in layout.constants:
                    probs.error(child, f"{where}: {name} is a constant of {self.type_name}")
                else:
                    known = ", ".join(f.xml for f in layout.fields) or "none"
                    probs.error(
                        child,
                        f"{where}: unknown parameter {name!r} ({self.type_name} has: {known})",
                    )
                continue
            if f.attr in seen:
                probs.error(child, f"{where}.{f.xml}: given twice (first on line {seen[f.attr]})")
                failed = True
                continue
            seen[f.attr] = child.sourceline or 0
            value = f.codec.read(child, getattr(current, f.attr), f"{where}.{f.xml}", probs)
            if value is FAIL:
                failed = True
            else:
                updates[f.attr] = value
        if failed:
            return FAIL
        return layout.replace(current, updates)

    def write(self, parent: etree._Element, name: str | None, value: Any, compact: bool) -> None:
        write_fields(self.layout, codecs.new_parameter(parent, name), value, compact)

    def show(self, value: Any) -> str:
        return "\n" + "\n".join("  " + line for line in show_lines(self.layout, value))


def write_fields(layout: Layout, elem: etree._Element, value: Any, compact: bool) -> None:
    for f in layout.fields:
        f.codec.write(elem, f.xml, getattr(value, f.attr), compact)


_UNITS = {id(ANGLE): "°", id(TIME): "s"}  # printed when the parameter has no measure


def show_lines(layout: Layout, value: Any) -> list[str]:
    """`Name: value unit` per parameter, nested structures indented (Miro's `operator<<`)."""
    lines: list[str] = []
    for f in layout.fields:
        v = getattr(value, f.attr)
        codec = f.codec
        if isinstance(codec, Struct):
            lines.append(f"{f.xml}:")
            lines += ["  " + line for line in show_lines(codec.layout, v)]
        elif isinstance(codec, Vector) and isinstance(codec.element, Struct):
            lines.append(f"{f.xml}: ({len(v)})")
            for i, item in enumerate(v):
                lines.append(f"  [{i}]:")
                lines += ["    " + line for line in show_lines(codec.element.layout, item)]
        else:
            unit = f.measure or _UNITS.get(id(codec))
            lines.append(f"{f.xml}: {codec.show(v)}" + (f" {unit}" if unit else ""))
    return lines


def read_into(target: Any, layout: Layout, elem: etree._Element, source: str | None) -> Any:
    """The value of `target` updated from `elem`'s children; `ParamsError` lists every problem."""
    path = source or elem.getroottree().docinfo.URL or "<xml>"
    probs = Problems(str(path))
    new = Struct(layout).read(elem, target, elem.get("name") or layout.cls.__name__, probs)
    if probs or new is FAIL:
        raise ParamsError(probs.items)
    return new


load_secrets()  # before pydantic.types imports it: no OpenSSL for a comparison never made


class Config(pydantic.BaseModel):
    """`Miro::Config`: the base of every parameter class.

    Fields are validated on assignment; unknown keyword arguments are errors (`extra="forbid"`),
    so a misspelt parameter is never silently ignored.
    """

    # defer_build: a class's validator is built when it first validates something (a keyword
    # argument, an assignment), not when its module is imported: a service that reads its
    # parameters and never assigns one builds none (pydantic's schema machinery: 3.6 MB and
    # tens of milliseconds at start).
    model_config = pydantic.ConfigDict(
        extra="forbid", validate_assignment=True, validate_default=False, defer_build=True
    )

    def __init__(self, /, **data: Any) -> None:
        """Validate `data`; without any (`instance()`, a default factory), every field gets
        its default, unvalidated as `validate_default=False` has it, and the `<constructor>`
        block runs: what validating nothing does, made by `model_construct` instead, so that
        the validator need not be built."""
        cls = type(self)
        if data or not _defaults_only(cls):
            super().__init__(**data)
            return
        made = cls.model_construct()
        for slot in _STATE:
            object.__setattr__(self, slot, getattr(made, slot))

    # (XML name, attribute, codec, measure) of the parameters this class adds
    _xml_fields: ClassVar[tuple[XmlField, ...]] = ()
    # names of its static_const parameters (class constants, not read from XML)
    _xml_constants: ClassVar[tuple[str, ...]] = ()

    def model_post_init(self, context: Any, /) -> None:
        """Run the `<constructor>` block (if any) for the fields the caller did not give."""
        if type(self)._construct is Config._construct:
            return
        given = {k: self.__dict__[k] for k in self.model_fields_set}
        fields_set = set(self.model_fields_set)
        self._construct()
        self.__dict__.update(given)
        object.__setattr__(self, "__pydantic_fields_set__", fields_set)

    def _construct(self) -> None:
        """Default-building statements of the item's `<constructor>` (generated)."""

    @classmethod
    def xml_layout(cls) -> Layout:
        return layout_of(cls)

    def from_xml(self, element: etree._Element, source: str | None = None) -> Self:
        """Update from a run-time `<parameter>` element (`params <<= element`). On any error
        raise `ParamsError` naming every problem, and change nothing."""
        new = read_into(self, layout_of(type(self)), element, source)
        if new is not self:
            fields = type(self).model_fields
            changed = {
                k: v for k, v in new.__dict__.items() if k in fields and v is not self.__dict__[k]
            }
            self.__dict__.update(changed)
            self.__pydantic_fields_set__.update(changed)
        return self

    def to_xml(self, name: str | None = "Parameters", compact: bool = False) -> etree._Element:
        """This object as a run-time `<parameter name=...>` element; `compact` writes vectors
        of numbers as one `value="1 2 3"` (matrices with rows separated by `;`)."""
        from lxml import etree

        root = etree.Element(codecs.PARAMETER)
        if name is not None:
            root.set("name", name)
        write_fields(layout_of(type(self)), root, self, compact)
        return root

    def write_xml(self, element: etree._Element, compact: bool = False) -> Self:
        """Append the parameters to `element` (`params >>= element`)."""
        write_fields(layout_of(type(self)), element, self, compact)
        return self

    def __ilshift__(self, element: etree._Element) -> Self:
        return self.from_xml(element)

    def __irshift__(self, element: etree._Element) -> Self:
        return self.write_xml(element)

    def __str__(self) -> str:
        return "\n".join(show_lines(layout_of(type(self)), self))


# What makes up a pydantic model's instance (the slots `model_construct` and `model_copy` set).
_STATE = ("__dict__", "__pydantic_fields_set__", "__pydantic_extra__", "__pydantic_private__")
_PLAIN: dict[type[Any], bool] = {}


def _defaults_only(cls: type[Config]) -> bool:
    """Whether an instance made of nothing is its defaults, unvalidated: no field is required
    and none validates its default."""
    plain = _PLAIN.get(cls)
    if plain is None:
        plain = _PLAIN[cls] = not cls.model_config.get("validate_default") and not any(
            f.is_required() or f.validate_default for f in cls.model_fields.values()
        )
    return plain


_INSTANCES: dict[type[Any], Any] = {}
_INSTANCE_LOCK = threading.Lock()


def instance_of(cls: type[T]) -> T:
    """The process-wide instance of a parameter class (an item with `instance="true"`)."""
    obj = _INSTANCES.get(cls)
    if obj is None:
        with _INSTANCE_LOCK:
            obj = _INSTANCES.get(cls)
            if obj is None:
                obj = _INSTANCES[cls] = cls()
    return obj


def resize(items: list[T], n: int, make: Callable[[], T]) -> None:
    """`v.resize(n)` / `seq.length(n)` of a constructor block: new elements are defaults."""
    if n < 0:
        raise ValueError(f"cannot resize to {n} elements")
    del items[n:]
    items.extend(make() for _ in range(n - len(items)))


def cxx_div(a: int, b: int) -> int:
    """C++ integer division (truncates towards zero), for constructor blocks."""
    if b == 0:
        raise ZeroDivisionError("integer division by zero in a <constructor> block")
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b >= 0) else -q


def cxx_mod(a: int, b: int) -> int:
    """C++ `%` (the sign of the dividend), for constructor blocks."""
    return a - cxx_div(a, b) * b


class SerialParams(Config):
    """`ACE_TTY_IO::Serial_Params`: a serial line's settings (`pyserial()` for `serial.Serial`)."""

    baudrate: int = 9600
    xonlim: int = 0
    xofflim: int = 0
    readmincharacters: int = 0
    readtimeoutmsec: int = 10000
    parityenb: bool = False
    paritymode: str = "none"
    ctsenb: bool = False
    rtsenb: int = 0
    xinenb: bool = False
    xoutenb: bool = False
    modem: bool = False
    rcvenb: bool = True
    dsrenb: bool = False
    databits: int = 8
    stopbits: int = 1

    _xml_fields = (
        XmlField("Baudrate", "baudrate", INT),
        XmlField("Xonlim", "xonlim", INT),
        XmlField("Xofflim", "xofflim", INT),
        XmlField("Readmincharacters", "readmincharacters", UINT),
        XmlField("Readtimeoutmsec", "readtimeoutmsec", INT, "msec"),
        XmlField("Parityenb", "parityenb", BOOL),
        XmlField("Paritymode", "paritymode", Enum(["none", "even", "odd", "mark", "space"])),
        XmlField("Ctsenb", "ctsenb", BOOL),
        XmlField("Rtsenb", "rtsenb", INT),
        XmlField("Xinenb", "xinenb", BOOL),
        XmlField("Xoutenb", "xoutenb", BOOL),
        XmlField("Modem", "modem", BOOL),
        XmlField("Rcvenb", "rcvenb", BOOL),
        XmlField("Dsrenb", "dsrenb", BOOL),
        XmlField("Databits", "databits", INT),
        XmlField("Stopbits", "stopbits", INT),
    )

    def pyserial(self) -> dict[str, Any]:
        """Keyword arguments for `serial.Serial(port, **params.pyserial())`."""
        return values.serial_settings(self)


class SchedParams(Config):
    """`ACE_Sched_Params`: a scheduling policy and priority (`apply()` sets them)."""

    policy: str = "SCHED_OTHER"
    priority: int = 0
    scope: str = "ACE_SCOPE_THREAD"
    quantum: datetime.timedelta = datetime.timedelta(0)

    _xml_fields = (
        XmlField("Policy", "policy", Enum(["SCHED_OTHER", "SCHED_FIFO", "SCHED_RR"])),
        XmlField("Priority", "priority", INT),
        XmlField(
            "Scope", "scope", Enum(["ACE_SCOPE_THREAD", "ACE_SCOPE_PROCESS", "ACE_SCOPE_LWP"])
        ),
        XmlField("Quantum", "quantum", TIME),
    )

    def apply(self, pid: int = 0) -> None:
        """Set this process's (or `pid`'s) scheduling policy and priority (Linux)."""
        policy = getattr(os, self.policy)
        os.sched_setscheduler(pid, policy, os.sched_param(self.priority))
