"""How each parameter type is read from, written to and printed from run-time XML.

A codec turns one `<parameter>` element into a Python value and back. Errors do not raise: they
are collected in a `Problems` list with the element's line, so that a document reports all its
mistakes at once; a failed read returns `FAIL` and the caller keeps its current value.
"""

from __future__ import annotations

import copy
import datetime
import math
import re
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final

from miro_gen.diagnostics import Diagnostic, SourcePos
from miro_gen.params.runtime import values

if TYPE_CHECKING:
    from lxml import etree  # imported where XML is made or parsed: a service without a
    # parameter document starts without lxml


class _Fail:
    def __repr__(self) -> str:
        return "FAIL"


FAIL: Final = _Fail()  # a value that could not be read; the problem is already reported

PARAMETER = "parameter"
_SPLIT = re.compile(r"[\s,]+")
_ROWS = re.compile(r"[;\n]")


class Problems:
    """The errors found in one document, each with the line of the element it concerns."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.items: list[Diagnostic] = []

    def error(self, elem: etree._Element | None, message: str) -> None:
        line = elem.sourceline if elem is not None and elem.sourceline else 0
        pos = SourcePos(self.path, line, 0) if line else None
        self.items.append(Diagnostic("error", pos, message))

    def __bool__(self) -> bool:
        return bool(self.items)


class Codec:
    """Base of all codecs: `label` is the type as the compile-time file spells it."""

    label = "?"
    xsd = "xs:string"  # the XML Schema type of its value= attribute (scalars)
    compact = False  # a vector of it may be written as one value="1 2 3"

    def default(self) -> Any:
        raise NotImplementedError

    def read(self, elem: etree._Element, current: Any, where: str, probs: Problems) -> Any:
        raise NotImplementedError

    def write(self, parent: etree._Element, name: str | None, value: Any, compact: bool) -> None:
        raise NotImplementedError

    def show(self, value: Any) -> str:
        raise NotImplementedError


def new_parameter(parent: etree._Element, name: str | None) -> etree._Element:
    from lxml import etree

    elem = etree.SubElement(parent, PARAMETER)
    if name is not None:
        elem.set("name", name)
    return elem


def _stray_text(elem: etree._Element, where: str, probs: Problems) -> None:
    """Text inside a `<parameter>` is not a value (Miro reads `value=` only): say so."""
    texts = [elem.text] + [c.tail for c in elem]
    if any(t is not None and t.strip() for t in texts):
        probs.error(elem, f"{where}: text inside <parameter> is not read; give it as value=...")


def children(elem: etree._Element, where: str, probs: Problems) -> list[etree._Element]:
    """The `<parameter>` children of an element; anything else is reported."""
    _stray_text(elem, where, probs)
    out = []
    for child in elem:
        if not isinstance(child.tag, str):
            continue  # comments and processing instructions
        if child.tag != PARAMETER:
            probs.error(child, f"{where}: unexpected element <{child.tag}> (expected <parameter>)")
            continue
        out.append(child)
    return out


class Scalar(Codec):
    """A value written in one `value="..."` attribute."""

    def __init__(
        self,
        label: str,
        parse: Callable[[str], Any],
        fmt: Callable[[Any], str],
        show: Callable[[Any], str] | None = None,
        default: Any = None,
        xsd: str = "xs:string",
        compact: bool = False,
    ) -> None:
        self.label = label
        self.parse = parse
        self.format = fmt
        self._show = show or fmt
        self._default = default
        self.xsd = xsd
        self.compact = compact

    def default(self) -> Any:
        return copy.deepcopy(self._default)

    def read(self, elem: etree._Element, current: Any, where: str, probs: Problems) -> Any:
        text = elem.get("value")
        if len(elem):
            probs.error(elem, f"{where}: a {self.label} takes value=..., not nested parameters")
            return FAIL
        _stray_text(elem, where, probs)
        if text is None:
            probs.error(elem, f"{where}: missing value=... (a {self.label})")
            return FAIL
        return self.read_text(text, elem, where, probs)

    def read_text(self, text: str, elem: etree._Element, where: str, probs: Problems) -> Any:
        try:
            return self.parse(text)
        except ValueError as e:
            probs.error(elem, f"{where}: {e}")
            return FAIL

    def write(self, parent: etree._Element, name: str | None, value: Any, compact: bool) -> None:
        new_parameter(parent, name).set("value", self.format(value))

    def show(self, value: Any) -> str:
        return self._show(value)


def _integer(label: str, lo: int, hi: int) -> Callable[[str], int]:
    def parse(text: str) -> int:
        t = text.strip()
        try:
            v = int(t, 16) if t.lower().startswith(("0x", "-0x", "+0x")) else int(t, 10)
        except ValueError:
            raise ValueError(f"expected an integer ({label}), got {text!r}") from None
        if not lo <= v <= hi:
            raise ValueError(f"{v} is outside the range of {label} ({lo}..{hi})")
        return v

    return parse


def _floating(label: str, limit: float) -> Callable[[str], float]:
    def parse(text: str) -> float:
        try:
            v = float(text.strip())
        except ValueError:
            raise ValueError(f"expected a number ({label}), got {text!r}") from None
        if math.isfinite(v) and abs(v) > limit:
            raise ValueError(f"{text.strip()} is outside the range of {label}")
        return v

    return parse


def parse_bool(text: str) -> bool:
    t = text.strip().lower()
    if t in ("true", "1", "yes", "on"):
        return True
    if t in ("false", "0", "no", "off"):
        return False
    raise ValueError(f"expected true or false, got {text!r}")


def parse_char(text: str) -> str:
    if len(text) != 1:
        raise ValueError(f"expected one character, got {text!r}")
    return text


def format_float(v: float) -> str:
    """Exact text for a float (shortest round-trip form); integers without `.0`."""
    if math.isfinite(v) and v == int(v) and abs(v) < 1e16:
        return str(int(v))
    return repr(v)


def show_float(v: float) -> str:
    """C++ ostream's default (`%g`, 6 digits): the manual prints `0 and 10`."""
    return f"{v:g}"


def _parse_angle(text: str) -> float:
    return values.deg2rad(_floating("angle", math.inf)(text))


def _format_angle(v: float) -> str:
    return format_float(values.rad2deg(v))


def _show_angle(v: float) -> str:
    return show_float(values.rad2deg(v))


def _show_time(v: datetime.timedelta) -> str:
    return show_float(v.total_seconds())


def integer(label: str, bits: int, signed: bool) -> Scalar:
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    return Scalar(
        label, _integer(label, lo, hi), str, default=0, xsd=_XSD_INT[(bits, signed)], compact=True
    )


_XSD_INT = {
    (8, True): "xs:byte",
    (16, True): "xs:short",
    (32, True): "xs:int",
    (64, True): "xs:long",
    (8, False): "xs:unsignedByte",
    (16, False): "xs:unsignedShort",
    (32, False): "xs:unsignedInt",
    (64, False): "xs:unsignedLong",
}

BOOL = Scalar("bool", parse_bool, lambda v: "true" if v else "false", default=False, xsd="boolFlag")
CHAR = Scalar("char", parse_char, str, default="\0", xsd="oneChar")
SHORT = integer("short", 16, True)
USHORT = integer("unsigned short", 16, False)
INT = integer("int", 32, True)
UINT = integer("unsigned int", 32, False)
LONG = integer("long", 64, True)  # LP64, as Miro's Linux builds
ULONG = integer("unsigned long", 64, False)
FLOAT = Scalar(
    "float",
    _floating("float", 3.4028234663852886e38),
    format_float,
    show_float,
    0.0,
    "xs:float",
    True,
)
DOUBLE = Scalar(
    "double", _floating("double", math.inf), format_float, show_float, 0.0, "xs:double", True
)
STRING = Scalar("string", str, str, default="")
ANGLE = Scalar("angle", _parse_angle, _format_angle, _show_angle, 0.0, "xs:double", True)
TIME = Scalar(
    "ACE_Time_Value",
    values.parse_time_value,
    values.format_time_value,
    _show_time,
    datetime.timedelta(0),
    "timeValue",
)
INET_ADDR = Scalar(
    "ACE_INET_Addr", values.parse_inet_addr, str, default=values.InetAddr("localhost", 0)
)


class Enum(Scalar):
    """`Enumeration`: a string from a fixed list of `values`."""

    def __init__(self, choices: Sequence[str]) -> None:
        self.choices = tuple(choices)
        allowed = frozenset(self.choices)

        def parse(text: str) -> str:
            t = text.strip()
            if t not in allowed:
                raise ValueError(f"{t!r} is not one of {', '.join(self.choices)}")
            return t

        super().__init__("Enumeration", parse, str, default=self.choices[0] if choices else "")


class Vector(Codec):
    """`vector<T>` / `set<T>`: `<parameter value="..."/>` per element, or one compact
    `value="1 2 3"` for numbers (rows separated by `;` for vectors of such vectors)."""

    def __init__(self, element: Codec, unique: bool = False, label: str | None = None) -> None:
        self.element = element
        self.unique = unique
        kind = "set" if unique else "vector"
        self.label = label or f"{kind}<{element.label}>"
        # numbers (and names from an enumeration) may be given in one value="1 2 3"
        self.compact = isinstance(element, Scalar) and (
            element.compact or isinstance(element, Enum)
        )
        self.matrix = isinstance(element, Vector) and element.compact and not element.unique

    def default(self) -> Any:
        return set() if self.unique else []

    def _finish(self, items: list[Any]) -> Any:
        return set(items) if self.unique else items

    def read(self, elem: etree._Element, current: Any, where: str, probs: Problems) -> Any:
        text = elem.get("value")
        kids = children(elem, where, probs)
        if text is not None:
            if kids:
                probs.error(elem, f"{where}: give the elements either in value= or as children")
                return FAIL
            return self.read_text(text, elem, where, probs)
        out: list[Any] = []
        failed = False
        for i, child in enumerate(kids):
            if child.get("name") is not None:
                probs.error(
                    child,
                    f"{where}: the elements of a {self.label} have no name= "
                    f"(got name={child.get('name')!r})",
                )
                failed = True
                continue
            value = self.element.read(child, self.element.default(), f"{where}[{i}]", probs)
            if value is FAIL:
                failed = True
            out.append(value)
        return FAIL if failed else self._finish(out)

    def read_text(self, text: str, elem: etree._Element, where: str, probs: Problems) -> Any:
        """The compact form: numbers separated by spaces or commas; matrix rows by `;`."""
        if self.matrix:
            assert isinstance(self.element, Vector)
            rows = [r for r in _ROWS.split(text) if r.strip()]
            out = [
                self.element.read_text(r, elem, f"{where}[{i}]", probs) for i, r in enumerate(rows)
            ]
            return FAIL if any(r is FAIL for r in out) else out
        if not self.compact:
            probs.error(
                elem,
                f"{where}: a {self.label} lists its elements as <parameter value=.../>; "
                "only vectors of numbers have a compact value=",
            )
            return FAIL
        scalar = self.element
        assert isinstance(scalar, Scalar)
        items = [t for t in _SPLIT.split(text.strip()) if t]
        out2 = [scalar.read_text(t, elem, f"{where}[{i}]", probs) for i, t in enumerate(items)]
        return FAIL if any(v is FAIL for v in out2) else self._finish(out2)

    def _ordered(self, value: Iterable[Any]) -> list[Any]:
        return sorted(value) if self.unique else list(value)

    def write(self, parent: etree._Element, name: str | None, value: Any, compact: bool) -> None:
        elem = new_parameter(parent, name)
        if compact and self.compact:
            elem.set("value", self.format_compact(value))
        elif compact and self.matrix:
            inner = self.element
            assert isinstance(inner, Vector)
            elem.set("value", "; ".join(inner.format_compact(row) for row in value))
        else:
            for item in self._ordered(value):
                self.element.write(elem, None, item, compact)

    def format_compact(self, value: Iterable[Any]) -> str:
        scalar = self.element
        assert isinstance(scalar, Scalar)
        return " ".join(scalar.format(v) for v in self._ordered(value))

    def show(self, value: Any) -> str:
        if self.matrix:
            inner = self.element
            return "[" + "; ".join(inner.show(row)[1:-1] for row in value) + "]"
        return "[" + " ".join(self.element.show(v) for v in self._ordered(value)) + "]"


def enum_multiple(choices: Sequence[str]) -> Vector:
    """`EnumerationMultiple`: several values of the list (`value="A, B"` or one per element)."""
    return Vector(Enum(choices), label="EnumerationMultiple")
