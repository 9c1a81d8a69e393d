"""The parameter objects of a running process, for its service object (`miro param`).

`ConfigDocument.get_parameters` (and so `read_parameters`) remembers each object it fills, with
its section, category and document, so that every service built on miro-gen exposes its
parameters without code of its own. A change from outside (`change`) is read exactly as a
run-time document is (the same codecs, checks and messages), applied all or nothing, and then
announced to the functions registered with `on_change`, which the service uses to react.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from lxml import etree  # imported where XML is made or parsed: a service without a
    # parameter document starts without lxml

SOURCE = "<set>"  # the name problems of a change are reported under


@dataclass
class Exposed:
    """A parameter object, where it belongs in a run-time document, and where it came from."""

    section: str
    category: str
    params: Any  # a Config
    document: str  # the document it was read from ("" when none)

    @property
    def type_name(self) -> str:
        cls = type(self.params)
        namespace = cls.__module__.split(".")[0]
        return f"{namespace}::{cls.__name__}"

    def element(self) -> etree._Element:
        """Its values as a run-time `<parameter name="CATEGORY">` element."""
        elem: etree._Element = self.params.to_xml(self.category)
        return elem


_lock = threading.Lock()
_exposed: list[Exposed] = []
_listeners: list[Callable[[Exposed], object]] = []


def remember(section: str, category: str, params: Any, document: str | None) -> None:
    """Record that `params` holds `category` of `section` (its latest reading wins)."""
    with _lock:
        for e in _exposed:
            if e.section == section and e.category == category:
                e.params, e.document = params, document or e.document
                return
        _exposed.append(Exposed(section, category, params, document or ""))


def exposed() -> list[Exposed]:
    with _lock:
        return list(_exposed)


def find(section: str, category: str) -> Exposed:
    """The set of `category` in `section` ('' for any section, when only one has it);
    LookupError saying what there is otherwise."""
    with _lock:
        found = [e for e in _exposed if e.category == category and section in ("", e.section)]
        known = [f"{e.section}/{e.category}" for e in _exposed]
    if len(found) == 1:
        return found[0]
    if found:
        where = ", ".join(f"{e.section}/{e.category}" for e in found)
        raise LookupError(f"{category} is in several sections ({where}): name the section")
    have = ", ".join(known) if known else "none"
    raise LookupError(f"no parameters {section + '/' if section else ''}{category} (has: {have})")


def change(target: Exposed, element: etree._Element) -> None:
    """Read `element` (a `<parameter name=CATEGORY>` with some of the values) into the
    object, as a run-time document is read; ParamsError and nothing changed on any problem.
    Then call the `on_change` functions."""
    target.params.from_xml(element, SOURCE)
    with _lock:
        listeners = list(_listeners)
    for fn in listeners:
        fn(target)


def on_change(fn: Callable[[Exposed], object]) -> None:
    """Call `fn(exposed)` after each change from outside (on the process's reactor thread, when
    the change came through its service object)."""
    with _lock:
        _listeners.append(fn)


def document() -> etree._Element:
    """Every exposed object as one run-time document (`<config>`), which `-MCF` reads back."""
    from lxml import etree

    root = etree.Element("config")
    sections: dict[str, etree._Element] = {}
    for e in exposed():
        section = sections.get(e.section)
        if section is None:
            section = sections[e.section] = etree.SubElement(root, "section", name=e.section)
        section.append(e.element())
    return root
