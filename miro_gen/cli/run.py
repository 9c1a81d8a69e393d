"""`miro run NAME [ARGS...]`: start a service in this process, exactly as Python would.

A service is found in the project in the current folder (`services/`, or `$MIRO_SERVICES`),
else among the services shipped with miro-gen (the manual's examples, the GPS driver):

* a package with `__init__.py` (what `miro new` writes) runs as `python -m services.NAME`;
* a folder with `__main__.py` (services/gps) runs as `python services/NAME`: its folder first
  on the path, so that its sibling modules import as they do there;
* a file (services/exampleA.py) runs as `python services/exampleA.py`: its folder first.

The project's `generated/` and the project itself are put on the path (and on PYTHONPATH, for
the processes a service starts). No second interpreter is started: the service runs in this
one, from `miro_gen.lifecycle`'s first line on, so Ctrl-C during its start ends it quietly.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from miro_gen import lifecycle, resources
from miro_gen.scaffold.names import name_problem

USAGE = """usage: miro run NAME [ARGS...]

Run the service NAME of the project in the current folder (services/NAME, or in the folder
$MIRO_SERVICES names), else the one shipped with miro-gen, as Python would run it (python -m
services.NAME for a package, python services/NAME for a folder or a file), with the project's
generated code on the path. ARGS are the service's own and the common options (--naming,
-MNC, -MLL, -MCF ...); `miro run NAME --help` lists them."""


@dataclass
class Service:
    path: Path  # the package folder, the folder with __main__.py, or the file
    module: str | None  # for a package: its module name (run with -m from `root`)
    root: Path  # the project it belongs to


def find(name: str, project: Path, folder: str) -> Service | None:
    """The service called `name`: the project's first, then the shipped ones."""
    places = [(project, project / folder)]
    shipped = resources.services_dir()
    if shipped is not None:
        places.append((shipped.parent, shipped))
    for root, services in places:
        base = services / name
        if (base / "__init__.py").is_file() and (base / "__main__.py").is_file():
            return Service(base, f"{services.name}.{name}", root)
        if (base / "__main__.py").is_file():
            return Service(base, None, root)
        if base.with_suffix(".py").is_file():
            return Service(base.with_suffix(".py"), None, root)
    return None


def available(project: Path, folder: str) -> list[str]:
    names: set[str] = set()
    for services in (project / folder, resources.services_dir()):
        if services is None or not services.is_dir():
            continue
        for entry in services.iterdir():
            if entry.suffix == ".py" and not entry.name.startswith("_"):
                names.add(entry.stem)
            elif (entry / "__main__.py").is_file():
                names.add(entry.name)
    return sorted(names)


def run_main(argv: Sequence[str]) -> int:
    lifecycle.defer_signals()  # first: a Ctrl-C from here on ends the service quietly
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE, file=sys.stderr if not argv else sys.stdout)
        return 2 if not argv else 0
    name, rest = argv[0], list(argv[1:])
    folder = os.environ.get("MIRO_SERVICES", "services")
    project = Path.cwd()
    service = find(name, project, folder)
    if service is None:
        print(f"miro run: {missing(name, project, folder)}", file=sys.stderr)
        return 1
    from miro_gen.cli.freshness import before_running

    if not before_running(service.root, "miro run"):  # never the old generated code
        return 1
    prepare(service, project, rest)
    lifecycle.run_main(lambda: execute(service), f"miro run {name}")


def missing(name: str, project: Path, folder: str) -> str:
    """Why there is no service `name`, and what there is."""
    where = project / folder
    text = f"no service {name!r} in {where}"
    problem = name_problem(name)
    if problem is None:
        text += f" (make one with `miro new {name}`)"
    else:
        text += f": {problem}"
    names = available(project, folder)
    if names:
        text += "; there are: " + ", ".join(names)
    return text


def prepare(service: Service, project: Path, args: list[str]) -> None:
    """Set sys.argv, sys.path and PYTHONPATH as `python ...` would for `service`, with the
    generated code of the project (and of the service's own checkout) on the path."""
    roots = dict.fromkeys([project, service.root])
    extra = [str(r / "generated") for r in roots if (r / "generated").is_dir()]
    if service.module is not None:
        sys.argv = [str(service.path / "__main__.py"), *args]
        first = str(service.root)  # python -m: the current folder first
        extra.append(first)
    else:
        sys.argv = [str(service.path), *args]
        first = str(service.path if service.path.is_dir() else service.path.parent)
    sys.path[0:1] = [first, *[p for p in extra if p not in sys.path and p != first]]
    paths = [*extra, os.environ.get("PYTHONPATH", "")]
    os.environ["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(p for p in paths if p))


def execute(service: Service) -> int:
    import runpy

    sys.stdout.flush()
    if service.module is not None:
        runpy.run_module(service.module, run_name="__main__", alter_sys=True)
    else:
        runpy.run_path(str(service.path), run_name="__main__")
    return 0
