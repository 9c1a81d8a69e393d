"""Writes a new service from templates/service/: validates the name, renders the pattern's files,
compiles its parameters (and its IDL, when given) with the project's own compilers."""

from __future__ import annotations

import importlib
import importlib.util
import keyword
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import jinja2

from miro_gen.codegen.render import template_dir
from miro_gen.scaffold.interface import Interface, InterfaceError, load_interface
from miro_gen.scaffold.patterns import PATTERNS, Parameter

NAME = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
MAX_NAME = 20  # characters: the files made from the templates then fit in 100 columns


class ScaffoldError(ValueError):
    """Why the service cannot be made (nothing has been written)."""


@dataclass
class File:
    path: str
    doc: str


def camel_case(name: str) -> str:
    """`gps_logger` -> `GpsLogger`: the service's class, parameter namespace and section."""
    return "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)


def check_name(name: str, target: Path) -> str:
    """The service's class name, after checking that `name` can be one and is free."""
    if not NAME.match(name) or keyword.iskeyword(name) or len(name) > MAX_NAME:
        raise ScaffoldError(
            f"{name!r} is not a service name: use lower-case letters, digits and single "
            f"underscores, starting with a letter, at most {MAX_NAME} characters (gps_logger)"
        )
    if target.exists():
        raise ScaffoldError(f"{target} exists already: nothing was written")
    camel = camel_case(name)
    if importlib.util.find_spec(camel) is not None:
        raise ScaffoldError(
            f"its parameters would be package {camel}, which exists already: choose another name"
        )
    return camel


def import_block(*sections: list[str]) -> str:
    """Import lines in the order ruff's isort wants them: each section (standard library, other
    packages, this package's modules) sorted, plain imports before from-imports, a blank line
    between sections. Templates say what they import; this says in which order."""

    def key(line: str) -> tuple[bool, str]:
        return line.startswith("from "), line.split()[1].lower()

    blocks = ["\n".join(sorted(set(section), key=key)) for section in sections if section]
    return "\n\n".join(blocks)


def from_import(module: str, names: list[str]) -> str:
    """`from module import a, B` with the names in ruff's order: constants, classes, others."""

    def key(name: str) -> tuple[int, str]:
        kind = 0 if name.isupper() else 1 if name[:1].isupper() else 2
        return kind, name.lower()

    ordered = sorted(set(names), key=key)
    line = f"from {module} import {', '.join(ordered)}"
    if len(line) <= 100:
        return line
    return f"from {module} import (\n" + "".join(f"    {n},\n" for n in ordered) + ")"


def separate_first_party(text: str, first_party: frozenset[str]) -> str:
    """`text` with the imports of `first_party` packages taken out of each block of imports
    into a block of their own, after the others: ruff's isort puts them in a section of their
    own. In miro-gen's own repository miro_gen is first-party; elsewhere it is one more
    package, sorted with the others, as the templates write it."""
    lines = text.split("\n")
    out: list[str] = []
    others: list[str] = []
    mine: list[str] = []
    current: list[str] | None = None  # the list the statement being read goes to

    def flush() -> None:
        out.extend(others)
        if others and mine:
            out.append("")
        out.extend(mine)
        others.clear()
        mine.clear()

    for line in lines:
        m = re.match(r"(?:from|import) ([\w.]+)", line)
        if m:
            current = mine if m.group(1).split(".")[0] in first_party else others
            current.append(line)
        elif current is not None and (line.startswith(" ") or line.startswith(")")):
            current.append(line)  # the rest of a statement in parentheses
        else:
            flush()
            current = None
            out.append(line)
    flush()
    return "\n".join(out)


def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(template_dir() / "service"),
        keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined,
        autoescape=False,
    )
    env.globals["imports"] = import_block
    env.globals["from_import"] = from_import
    return env


def compile_idl(idl: Path, project: Path, include_dirs: list[str]) -> None:
    """`miro-idl -o generated IDL` into the project, so the interface can be imported."""
    from miro_gen.cli import idl as idl_cli

    out = project / "generated"
    if idl_cli.main(["-o", str(out), *(f"-I{d}" for d in include_dirs), str(idl)]) != 0:
        raise ScaffoldError(f"{idl} does not compile (see above): nothing was written")
    if str(out) not in sys.path:
        sys.path.insert(0, str(out))
    importlib.invalidate_caches()


def scaffold(
    name: str,
    pattern: str,
    *,
    project: Path,
    folder: str = "services",
    interface: str | None = None,
) -> list[Path]:
    """Write service `name` of `pattern` into `project/folder/name`; the files written."""
    spec = PATTERNS[pattern]
    target = project / folder / name
    camel = check_name(name, target)
    iface: Interface | None = None
    if spec.interface:
        try:
            iface = load_interface(interface or spec.interface)
        except InterfaceError as e:
            raise ScaffoldError(str(e)) from None
        if pattern == "client" and iface.getter is None:
            raise ScaffoldError(
                f"{iface.scoped} has no operation without arguments that returns something, "
                "for the client to poll"
            )
    elif interface:
        raise ScaffoldError(f"the {pattern} pattern uses no --interface (server and client do)")
    fill = {"camel": camel, "interface": iface.scoped if iface else "", "server": ""}
    if iface is not None:
        fill["server"] = iface.cls.split(".")[-1]
    parameters = [
        Parameter(p.name, p.type, p.default.format(**fill), p.doc, p.measure, p.inherited)
        for p in spec.parameters
    ]
    modules = [("__init__.py", "the package; puts the project's generated code on the path")]
    modules += [("__main__.py", "the Base: starts the service (`main`)"), *spec.modules]
    files = [File(f"{folder}/{name}/{m}", doc) for m, doc in modules]
    files += [
        File(f"{folder}/{name}/Parameters.xml", "its parameters (compile-time, for miro-params)"),
        File(f"generated/{camel}/Parameters.py", "their generated module (miro-params)"),
        File(f"{folder}/{name}/test_{name}.py", "its test: it runs against a naming service"),
    ]
    rate = next((float(p.default) for p in parameters if p.name == "Rate"), 10.0)
    context = {
        "name": name,
        "camel": camel,
        "category": camel.upper(),
        "folder": folder,
        "pattern": pattern,
        "pattern_doc": spec.doc,
        "summary": spec.summary.format(**fill),
        "parameters": parameters,
        "parent": spec.parent,
        "iface": iface,
        "files": files,
        "default_server": fill["server"],
        "default_channel": "EventChannel",
        "rate": f"{rate:g}",
        "rate_low": int(rate * 0.7),
        "rate_high": int(rate * 1.3) + 1,
    }
    env = _environment()
    outputs = {"__init__.py": "common/__init__.py.j2", "__main__.py": f"{pattern}/__main__.py.j2"}
    outputs.update({m: f"{pattern}/{m}.j2" for m, _ in spec.modules})
    outputs["Parameters.xml"] = "common/Parameters.xml.j2"
    outputs["README.md"] = "common/README.md.j2"
    outputs[f"test_{name}.py"] = f"{pattern}/test.py.j2"
    rendered = {out: env.get_template(tpl).render(context) for out, tpl in outputs.items()}
    if (project / "miro_gen" / "__init__.py").is_file():  # miro-gen's own repository
        mine = frozenset({"miro_gen"})
        rendered = {
            out: separate_first_party(text, mine) if out.endswith(".py") else text
            for out, text in rendered.items()
        }
    target.mkdir(parents=True)
    written = []
    for out, text in rendered.items():
        path = target / out
        path.write_text(text)
        written.append(path)
    from miro_gen.cli import params as params_cli

    if params_cli.main(["-o", str(project / "generated"), str(target / "Parameters.xml")]) != 0:
        raise ScaffoldError(f"{target / 'Parameters.xml'} does not compile (see above)")
    return written
