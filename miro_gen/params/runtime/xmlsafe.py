"""Reading XML safely: lxml with entity resolution, DTD loading and network access off.

Parameter files are read at start-up of every service, often from a robot's shared folders, so a
hostile or broken file must never expand entities (billion laughs), read other files (external
entities) or reach the network. Miro's compile-time files use HTML's named character entities in
`measure` (`&deg;`, `&micro;`); without their DTD, libxml2 would silently drop them from attribute
values, so the names of HTML's table are replaced by their characters before parsing. Any other
entity reference is an error, and so is a DOCTYPE that declares entities.
"""

from __future__ import annotations

import html.entities
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen.diagnostics import Diagnostic, SourcePos

if TYPE_CHECKING:
    from lxml import etree

# The named entities Miro's files use come from HTML 4's table (ISO Latin-1, symbols, Greek).
ENTITIES: dict[str, str] = {
    name: chr(code)
    for name, code in html.entities.name2codepoint.items()
    if name not in ("amp", "lt", "gt", "quot", "apos")
}
DEFAULT_MAX_BYTES = 8 * 1024 * 1024
_XML_PREDEFINED = frozenset(["amp", "lt", "gt", "quot", "apos"])
_ENTITY_REF = re.compile(r"&([A-Za-z_][\w.-]*);")
_DOCTYPE_SUBSET = re.compile(rb"<!DOCTYPE[^>\[]*\[", re.I)


class XmlError(Exception):
    """The document cannot be used; carries every problem found (usually one)."""

    def __init__(self, diagnostics: list[Diagnostic]) -> None:
        self.diagnostics = diagnostics
        super().__init__("\n".join(str(d) for d in diagnostics))


def _error(path: str, line: int, col: int, message: str) -> Diagnostic:
    return Diagnostic("error", SourcePos(path, line, col), message)


def _replace_entities(text: str, path: str, problems: list[Diagnostic]) -> str:
    """Replace the built-in named entities by their characters; report unknown ones."""
    if "&" not in text:
        return text

    def sub(m: re.Match[str]) -> str:
        name = m.group(1)
        if name in _XML_PREDEFINED:
            return m.group(0)
        char = ENTITIES.get(name)
        if char is not None:
            return char
        line = text.count("\n", 0, m.start()) + 1
        col = m.start() - (text.rfind("\n", 0, m.start()) + 1) + 1
        problems.append(_error(path, line, col, f"unknown entity '&{name};'"))
        return m.group(0)

    return _ENTITY_REF.sub(sub, text)


def max_bytes() -> int:
    """The largest document read: `MIRO_PARAMS_MAX_BYTES`, else 8 MiB. A parsed document
    takes about 28 times its size in memory; Miro's documents are kilobytes."""
    text = os.environ.get("MIRO_PARAMS_MAX_BYTES", "")
    return int(text) if text.isdigit() and int(text) > 0 else DEFAULT_MAX_BYTES


def _too_large(path: str, limit: int) -> XmlError:
    message = (
        f"the document is larger than {limit} bytes, the limit for parameter documents "
        "(set MIRO_PARAMS_MAX_BYTES to allow more)"
    )
    return XmlError([Diagnostic("error", SourcePos(path, 1, 0), message)])


def parse_xml(data: bytes | str, path: str) -> etree._ElementTree:
    """Parse a document safely; raise `XmlError` with `path:line:col` positions."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    limit = max_bytes()
    if len(raw) > limit:
        raise _too_large(path, limit)
    m = _DOCTYPE_SUBSET.search(raw)
    if m is not None and b"<!ENTITY" in raw[m.end() :].split(b"]>", 1)[0].upper():
        line = raw.count(b"\n", 0, m.start()) + 1
        raise XmlError(
            [
                _error(
                    path,
                    line,
                    0,
                    "the DOCTYPE declares entities; such documents are refused "
                    "(entity expansion and external entities are never processed)",
                )
            ]
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        raise XmlError([_error(path, line, 0, "the file is not UTF-8 text")]) from None
    problems: list[Diagnostic] = []
    text = _replace_entities(text, path, problems)
    if problems:
        raise XmlError(problems)
    from lxml import etree  # here: importing this module costs no lxml

    parser = etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        huge_tree=False,
        remove_comments=True,
        remove_pis=True,
    )
    try:
        root = etree.fromstring(_strip_declaration(text).encode("utf-8"), parser)
    except etree.XMLSyntaxError as e:
        line, col = e.position if e.position else (0, 0)
        message = str(e.msg or "not well-formed XML")
        message = re.sub(r", line \d+, column \d+.*$", "", message)
        raise XmlError([_error(path, line, col, f"XML: {message}")]) from None
    tree = root.getroottree()
    dtd = tree.docinfo.internalDTD
    if dtd is not None and any(True for _ in dtd.iterentities()):  # pragma: no cover - see above
        raise XmlError([_error(path, 1, 0, "the DOCTYPE declares entities; refused")])
    return tree


def _strip_declaration(text: str) -> str:
    """An XML declaration naming an encoding is not allowed in a str for lxml; the text is
    already decoded, so keep the line (for line numbers) and drop the declaration itself."""
    if text.startswith("\ufeff"):
        text = text[1:]
    if text.startswith("<?xml"):
        end = text.find("?>")
        if end != -1:
            return " " * (end + 2) + text[end + 2 :]
    return text


def read_xml(path: str | Path) -> etree._ElementTree:
    """Read and parse a file safely (see `parse_xml`); a file over the size limit is refused
    before it is read (reading stops there, also for devices and pipes)."""
    limit = max_bytes()
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError as e:
        raise XmlError(
            [Diagnostic("error", None, f"cannot read '{path}': {e.strerror or e}")]
        ) from None
    if len(data) > limit:
        raise _too_large(str(path), limit)
    return parse_xml(data, str(path))
