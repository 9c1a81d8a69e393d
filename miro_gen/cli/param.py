"""`miro param get|set|dump SERVICE [NAME [VALUE]]`: the parameters of a running service
(Miro's ConfigEditor and MakeConfig), through its service object.

A NAME is `Category.Parameter.Field` (or `Section/Category.Parameter`, or a parameter's own name
when only one set has it). `set` changes one value as a run-time document would (checked the
same way; all or nothing), and the service announces it (a ParametersChanged event). `dump`
writes every set as a run-time document, which `-MCF FILE` reads back.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lxml import etree

from miro_gen.cli.liveargs import connect
from miro_gen.cli.verbs import verb
from miro_gen.live.remote import LiveError, Running


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro param",
        description="Read, change or dump the parameters of a running service (any service "
        "built on miro-gen's Server that reads a run-time document). Accepts the common "
        "options (--naming tcp://HOST:PORT).",
    )
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    actions = {v.name: sub.add_parser(v.name, help=v.help) for v in verb("param").subs}
    get = actions["get"]
    get.add_argument("service", metavar="SERVICE", help="gps, robot1/gps, or an object's name")
    get.add_argument("name", metavar="NAME", nargs="?", help="Category[.Parameter[.Field]]")
    get.add_argument("--xml", action="store_true", help="as run-time document elements")
    put = actions["set"]
    put.add_argument("service", metavar="SERVICE")
    put.add_argument("name", metavar="NAME", help="Category.Parameter[.Field]")
    put.add_argument(
        "value",
        metavar="VALUE",
        help="its new value, as a document writes it ('1 2 3' for a "
        "vector); a YAML list or mapping for a vector or a structure",
    )
    out = actions["dump"]
    out.add_argument("service", metavar="SERVICE")
    out.add_argument("-o", "--output", metavar="FILE", help="write it to FILE (default: stdout)")
    return p


def param_main(argv: Sequence[str]) -> int:
    p = parser()
    robot, ns = connect(p, "miro param", argv)
    try:
        service = robot.service(ns.service)
        if service.description is None:
            raise LiveError(f"{service.name} does not answer: {service.error}")
        stub = robot.service_at(service.entry.endpoint, timeout=robot.timeout)
        return int({"get": _get, "set": _set, "dump": _dump}[ns.action](stub, service, ns))
    except LiveError as e:
        print(f"miro param: {e}", file=sys.stderr)
        return 1
    finally:
        robot.close()


# ---- names -------------------------------------------------------------------------------------


def _sets(service: Running) -> list[tuple[str, str]]:
    assert service.description is not None
    return [(s.section, s.category) for s in service.description.parameters]


def _target(service: Running, stub: Any, name: str) -> tuple[str, str, list[str]]:
    """(section, category, path inside it) of NAME."""
    sets = _sets(service)
    if not sets:
        raise LiveError(f"{service.name} has no parameters (it read no run-time document)")
    head, _, rest = name.partition(".")
    section, _, category = head.rpartition("/")
    matches = [(s, c) for s, c in sets if c.lower() == category.lower() and section in ("", s)]
    if matches:
        if len(matches) > 1:
            raise LiveError(f"{category} is in several sections: write SECTION/{name}")
        s, c = matches[0]
        return s, c, [p for p in rest.split(".") if p]
    # a parameter's own name: the one set that has it
    path = [p for p in name.split(".") if p]
    found = [(s, c) for s, c in sets if _find(_element(stub, s, c), path) is not None]
    if len(found) == 1:
        return found[0][0], found[0][1], path
    have = ", ".join(f"{s}/{c}" for s, c in sets)
    if found:
        raise LiveError(f"{name} is in several sets ({have}): write CATEGORY.{name}")
    raise LiveError(f"{service.name} has no parameter {name} (its sets: {have})")


def _element(stub: Any, section: str, category: str) -> etree._Element:
    import MiroService

    from miro_gen.exceptions import SystemException

    try:
        text = stub.get_parameters(section, category)
    except MiroService.NotFound as e:
        raise LiveError(e.what) from None
    except SystemException as e:
        raise LiveError(str(e)) from None
    return etree.fromstring(text.encode())


def _find(elem: etree._Element, path: list[str]) -> etree._Element | None:
    found: etree._Element | None = elem
    for part in path:
        assert found is not None
        found = next((c for c in found if str(c.get("name", "")).lower() == part.lower()), None)
        if found is None:
            return None
    return found


def tree_text(value: Any, indent: str = "") -> str:
    """Plain parameter data as `Name: value` lines (values as a document writes them)."""
    if isinstance(value, dict):
        lines = []
        for key, item in value.items():
            if isinstance(item, dict | list) and item:
                lines += [f"{indent}{key}:", tree_text(item, indent + "  ")]
            else:
                lines.append(f"{indent}{key}: {item if item != [] else '(none)'}")
        return "\n".join(lines)
    if isinstance(value, list):
        return "\n".join(
            f"{indent}-\n{tree_text(item, indent + '  ')}"
            if isinstance(item, dict | list)
            else f"{indent}- {item}"
            for item in value
        )
    return f"{indent}{value}"


def plain(elem: etree._Element) -> Any:
    """A run-time `<parameter>` element as plain data: its value, a mapping of its named
    children, or a list of its unnamed ones."""
    children = [c for c in elem if isinstance(c.tag, str)]
    if not children:
        return elem.get("value", "")
    if all(c.get("name") is None for c in children):
        return [plain(c) for c in children]
    return {str(c.get("name")): plain(c) for c in children}


# ---- actions -----------------------------------------------------------------------------------


def _get(stub: Any, service: Running, ns: argparse.Namespace) -> int:
    if ns.name is None:
        for section, category in _sets(service):
            elem = _element(stub, section, category)
            if ns.xml:
                print(etree.tostring(elem, encoding="unicode", pretty_print=True).rstrip())
            else:
                print(f"{section}/{category}:")
                print(tree_text(plain(elem), "  "))
        return 0
    section, category, path = _target(service, stub, ns.name)
    found = _find(_element(stub, section, category), path)
    if found is None:
        raise LiveError(f"{section}/{category} has no parameter {'.'.join(path)}")
    elem = found
    if ns.xml:
        print(etree.tostring(elem, encoding="unicode", pretty_print=True).rstrip())
    else:
        print(tree_text(plain(elem)))
    return 0


def _set(stub: Any, service: Running, ns: argparse.Namespace) -> int:
    import MiroService

    from miro_gen.exceptions import SystemException
    from miro_gen.launch.documents import fill_element

    section, category, path = _target(service, stub, ns.name)
    if not path:
        raise LiveError("name the parameter to set: CATEGORY.PARAMETER")
    root = etree.Element("parameter", name=category)
    elem = root
    for part in path:
        elem = etree.SubElement(elem, "parameter", name=part)
    fill_element(elem, _value(ns.value))
    try:
        text = stub.set_parameters(section, category, etree.tostring(root, encoding="unicode"))
    except MiroService.InvalidParameters as e:
        for problem in e.problems:
            print(f"miro param: {problem}", file=sys.stderr)
        return 1
    except MiroService.NotFound as e:
        raise LiveError(e.what) from None
    except SystemException as e:
        raise LiveError(str(e)) from None
    now = _find(etree.fromstring(text.encode()), path)
    shown = tree_text(plain(now)) if now is not None else "?"
    print(f"{section}/{category}.{'.'.join(path)} = {shown}")
    return 0


def _value(text: str) -> Any:
    """VALUE: a YAML list or mapping when it looks like one, else the text as it is."""
    if text.strip()[:1] in ("[", "{"):
        import yaml

        try:
            return yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise LiveError(f"cannot read {text!r}: {getattr(e, 'problem', e)}") from None
    return text


def _dump(stub: Any, service: Running, ns: argparse.Namespace) -> int:
    from miro_gen.exceptions import SystemException

    try:
        text = stub.dump_parameters()
    except SystemException as e:
        raise LiveError(str(e)) from None
    if ns.output:
        Path(ns.output).write_text(text + "\n", encoding="utf-8")
        print(f"wrote {ns.output}", file=sys.stderr)
    else:
        print(text)
    return 0
