"""Run-time parameter documents for launched services: a launch file's inline `parameters`
tables, written as the document `-MCF` reads (over a document of the file's, when both are
given: the inline values replace the document's values of the same name).

    [services.gps.parameters.Gps.Gps]       # section Gps, category Gps
    Device = "/tmp/gps0"
    TtyParams = { Baudrate = 9600 }         # a structure: nested parameters
    Ranges = [1, 2, 3]                      # a vector: one <parameter value=.../> per element

The service itself checks the values when it reads them, exactly as any document's; an error
names this file and line, and the launch file's table in a comment above it.
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import Any

from lxml import etree

PARAMETER = "parameter"


def value_text(value: Any) -> str:
    """A TOML value as a run-time document writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and value.is_integer():
        return repr(value)
    if isinstance(value, datetime.time | datetime.date | datetime.datetime):
        return value.isoformat()
    return str(value)


def fill_element(elem: etree._Element, value: Any) -> None:
    """Make `elem` (a `<parameter>`) hold `value`: a scalar in `value=`, a table as named
    children, a list as unnamed children."""
    for child in list(elem):
        elem.remove(child)
    if "value" in elem.attrib:
        del elem.attrib["value"]
    if isinstance(value, dict):
        for name, item in value.items():
            fill_element(etree.SubElement(elem, PARAMETER, name=str(name)), item)
    elif isinstance(value, list):
        for item in value:
            fill_element(etree.SubElement(elem, PARAMETER), item)
    else:
        elem.set("value", value_text(value))


def _child(parent: etree._Element, tag: str, name: str) -> etree._Element:
    for child in parent:
        if child.tag == tag and child.get("name") == name:
            return child
    return etree.SubElement(parent, tag, name=name)


def merge(root: etree._Element, parameters: dict[str, Any]) -> None:
    """Set `parameters` (SECTION -> CATEGORY -> NAME -> value) in the document `root`."""
    for section, categories in parameters.items():
        sec = _child(root, "section", str(section))
        for category, values in categories.items():
            cat = _child(sec, PARAMETER, str(category))
            for name, value in values.items():
                fill_element(_child(cat, PARAMETER, str(name)), value)


def write_parameters(path: Path, base: Path | None, parameters: dict[str, Any]) -> Path:
    """Write the document for a service to `path`: `base` (if any) with `parameters` set in
    it; `path`."""
    if base is not None:
        from miro_gen.params.runtime.xmlsafe import XmlError, read_xml

        try:
            root = read_xml(str(base)).getroot()
        except XmlError as e:
            raise ValueError("; ".join(str(d) for d in e.diagnostics)) from None
    else:
        root = etree.Element("config")
    merge(root, parameters)
    etree.indent(root, space="  ")
    path.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8") + b"\n")
    return path
