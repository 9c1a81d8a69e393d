"""`ConfigDocument`: the run-time parameter document of a service (Miro's `Miro::ConfigDocument`).

    <config>
      <section name="test">
        <parameter name="Test"> ... </parameter>
        <instance name="Front" type="Laser::Parameters"> ... </instance>
      </section>
    </config>

The document is `-MiroConfigFile FILE` / `-MCF FILE` from `argv`, else `<hostname>.xml` found in the
working folder and then in `$MIRO_ROOT/etc`. Without any, every service runs on its defaults, and
the paths looked for are logged once at notice level (`-MLL 5` shows them).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from miro_gen.diagnostics import Diagnostic, SourcePos
from miro_gen.log import logger
from miro_gen.params.runtime import live
from miro_gen.params.runtime.config import Config, ParamsError

if TYPE_CHECKING:
    from lxml import etree  # imported where XML is made or parsed: a service without a
    # parameter document starts without lxml

ROOT_TAG = "config"
_log = logger("ConfigDocument")
_reported: set[tuple[str, ...]] = set()  # the searches already reported as finding nothing


class Instance(NamedTuple):
    """An `<instance name="..." type="...">` of a section: a named parameter set."""

    name: str
    type: str
    element: etree._Element


def config_file_option(argv: Sequence[str]) -> str | None:
    """The value of `-MiroConfigFile` / `-MCF` in `argv` (the last one given), or None."""
    found = None
    for i, arg in enumerate(argv):
        if arg in ("-MCF", "-MiroConfigFile") and i + 1 < len(argv):
            found = argv[i + 1]
    return found


def search_path() -> list[Path]:
    """Where `<hostname>.xml` is looked for: `.` then `$MIRO_ROOT/etc`."""
    out = [Path(".")]
    root = os.environ.get("MIRO_ROOT")
    if root:
        out.append(Path(root) / "etc")
    return out


def find_document(argv: Sequence[str]) -> Path | None:
    """The run-time document `argv` names, else the first `<hostname>.xml` on the search path."""
    named = config_file_option(argv)
    if named is not None:
        return Path(named)
    name = socket.gethostname().split(".")[0] + ".xml"
    looked = [folder / name for folder in search_path()]
    for path in looked:
        if path.is_file():
            return path
    key = tuple(str(p.resolve()) for p in looked)
    if key not in _reported:  # once per process and search
        _reported.add(key)
        _log.notice(
            "no run-time parameter document (looked for %s; give one with -MCF FILE): "
            "every parameter keeps its default",
            " and ".join(str(p.resolve()) for p in looked),
        )
    return None


class ConfigDocument:
    """A run-time parameter document. Errors in it raise `ParamsError` (`path:line: error:`)."""

    def __init__(
        self,
        argv: Sequence[str] | None = None,
        *,
        path: str | Path | None = None,
        text: str | bytes | None = None,
    ) -> None:
        self.section: str | None = None
        self.path: str | None = None
        self._root: etree._Element | None = None  # None: no document, defaults everywhere
        if text is not None:
            self.path = str(path) if path is not None else "<string>"
            self._root = self._load(text)
            return
        if path is None:
            found = find_document(list(argv or []))
            if found is None:
                return
            path = found
        self.path = str(path)
        self._root = self._load(None)

    @property
    def root(self) -> etree._Element:
        """The document's `<config>` element (an empty one when there is no document)."""
        if self._root is None:
            from lxml import etree

            self._root = etree.Element(ROOT_TAG)
        return self._root

    def _load(self, text: str | bytes | None) -> etree._Element:
        """The document's root: `text`, else the file at `self.path` (checked: xmlsafe.py)."""
        from miro_gen.params.runtime.xmlsafe import XmlError, parse_xml, read_xml

        path = self.path or "<string>"
        try:
            tree = read_xml(path) if text is None else parse_xml(text, path)
        except XmlError as e:
            raise ParamsError(e.diagnostics) from None
        root = tree.getroot()
        if root.tag != ROOT_TAG:
            raise ParamsError(
                [self._diag(root, f"the root element is <{root.tag!s}>, expected <{ROOT_TAG}>")]
            )
        problems = [
            self._diag(child, f"unexpected element <{child.tag}> (expected <section name=...>)")
            for child in root
            if isinstance(child.tag, str) and child.tag != "section"
        ]
        problems += [
            self._diag(child, "a <section> needs a name=")
            for child in root
            if child.tag == "section" and child.get("name") is None
        ]
        if problems:
            raise ParamsError(problems)
        return root

    def _diag(self, elem: etree._Element, message: str) -> Diagnostic:
        return Diagnostic(
            "error", SourcePos(self.path or "<xml>", elem.sourceline or 0, 0), message
        )

    def sections(self) -> list[str]:
        return [s.get("name", "") for s in self._elements() if s.tag == "section"]

    def _elements(self) -> list[etree._Element]:
        return [] if self._root is None else list(self._root)

    def set_section(self, name: str) -> None:
        """Choose the section that `get_parameters` and `get_instances` read (Miro's
        `setSection`)."""
        self.section = name

    def _section_elements(self) -> list[etree._Element]:
        if self.section is None:
            raise ValueError("call set_section(name) before reading parameters")
        return [s for s in self._elements() if s.tag == "section" and s.get("name") == self.section]

    def find(self, category: str) -> etree._Element | None:
        """The `<parameter name="category">` of the current section; a second one is an error."""
        found: list[etree._Element] = [
            p
            for s in self._section_elements()
            for p in s
            if p.tag == "parameter" and p.get("name") == category
        ]
        if len(found) > 1:
            raise ParamsError(
                [
                    self._diag(
                        found[1],
                        f"parameter {category!r} given twice in section {self.section!r} "
                        f"(first on line {found[0].sourceline})",
                    )
                ]
            )
        return found[0] if found else None

    def get_parameters(self, category: str, params: Config) -> bool:
        """Update `params` from `<parameter name="category">` of the current section (Miro's
        `getParameters`). Returns whether the document had it; without it the values stay.
        Any error raises `ParamsError` listing every problem, and `params` is left unchanged."""
        elem = self.find(category)
        if elem is not None:
            params.from_xml(elem, self.path)
        live.remember(self.section or "", category, params, self.path)  # for `miro param`
        return elem is not None

    def get_instances(self, type_name: str) -> list[Instance]:
        """The `<instance name="..." type="type_name">` elements of the current section."""
        return [
            Instance(i.get("name", ""), i.get("type", ""), i)
            for s in self._section_elements()
            for i in s
            if i.tag == "instance" and i.get("type") == type_name
        ]

    def get_instance(self, instance: Instance, params: Config) -> None:
        """Update `params` from an instance's parameters."""
        params.from_xml(instance.element, self.path)


def read_parameters(
    params: Config, section: str, category: str | None = None, config_file: str | None = None
) -> bool:
    """A service's start-up read: `params` from `category` (default: `section`) of `section` in
    `config_file` (a Server's `options.config_file`, from `-MCF`), else in `<hostname>.xml` on the
    search path; the defaults stay when there is no document or it does not mention them.
    Whether the document had the category. ParamsError when the document is wrong."""
    document = ConfigDocument(path=config_file) if config_file else ConfigDocument([])
    document.set_section(section)
    return document.get_parameters(category or section, params)
