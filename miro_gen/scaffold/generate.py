"""Writes a new service from templates/service/: validates the name, renders the pattern's files,
compiles its parameters (and its IDL, when given) with the project's own compilers."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import jinja2

from miro_gen import resources
from miro_gen.scaffold.interface import WIDTH, Interface, InterfaceError, load_interface
from miro_gen.scaffold.names import name_problem
from miro_gen.scaffold.patterns import PATTERNS, Parameter

if TYPE_CHECKING:
    from miro_gen.compile.outcome import Outcome


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
    problem = name_problem(name)
    if problem is not None:
        raise ScaffoldError(problem)
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

    def stdlib(line: str) -> bool:
        return line.split()[1].split(".")[0] in sys.stdlib_module_names

    # The standard library's modules first, whichever section a template named them in.
    std = [line for section in sections for line in section if stdlib(line)]
    rest = [[line for line in section if not stdlib(line)] for section in sections]
    blocks = ["\n".join(sorted(set(section), key=key)) for section in (std, *rest) if section]
    return "\n\n".join(blocks)


def from_import(module: str, names: list[str]) -> str:
    """`from module import a, B` with the names in ruff's order: constants, classes, others."""

    def key(name: str) -> tuple[int, str]:
        kind = 0 if name.isupper() else 1 if name[:1].isupper() else 2
        return kind, name.lower()

    ordered = sorted(set(names), key=key)
    line = f"from {module} import {', '.join(ordered)}"
    if len(line) <= WIDTH:
        return line
    return f"from {module} import (\n" + "".join(f"    {n},\n" for n in ordered) + ")"


def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(resources.template_dir() / "service"),
        keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined,
        autoescape=False,
    )
    env.globals["imports"] = import_block
    env.globals["from_import"] = from_import
    return env


def compile_idl(idl: Path, project: Path, include_dirs: list[str]) -> None:
    """Compile `idl` into `project/generated` (as `miro-idl -o generated` run in the project
    would), so that the interface can be imported; its problems are printed, and make a
    ScaffoldError."""
    from miro_gen.compile.idl import idl_package

    out = project / "generated"
    done = idl_package([str(idl)], out, include_dirs=include_dirs, base=project)
    _report(done, f"{idl} does not compile (see above): nothing was written")
    if str(out) not in sys.path:
        sys.path.insert(0, str(out))
    importlib.invalidate_caches()


def compile_parameters(xml: Path, project: Path) -> list[Path]:
    """Compile a service's Parameters.xml into `project/generated` (as `miro-params -o
    generated` run in the project would); the files written."""
    from miro_gen.compile.params import params_package

    done = params_package([str(xml)], project / "generated", base=project)
    _report(done, f"{xml} does not compile (see above)")
    return done.paths()


def _report(done: Outcome, failed: str) -> None:
    """Print a compile's diagnostics and warnings; ScaffoldError(`failed`) when it failed."""
    for d in done.diagnostics:
        print(d, file=sys.stderr)
    for text in [*done.warnings, *done.errors]:
        print(f"miro new: {text}", file=sys.stderr)
    if not done.ok:
        raise ScaffoldError(failed)


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
    }
    env = _environment()
    outputs = {"__init__.py": "common/__init__.py.j2", "__main__.py": f"{pattern}/__main__.py.j2"}
    outputs.update({m: f"{pattern}/{m}.j2" for m, _ in spec.modules})
    outputs["Parameters.xml"] = "common/Parameters.xml.j2"
    outputs["README.md"] = "common/README.md.j2"
    outputs[f"test_{name}.py"] = f"{pattern}/test.py.j2"
    rendered = {out: env.get_template(tpl).render(context) for out, tpl in outputs.items()}
    target.mkdir(parents=True)
    written = []
    for out, text in rendered.items():
        path = target / out
        path.write_text(text)
        written.append(path)
    return written + compile_parameters(target / "Parameters.xml", project)
