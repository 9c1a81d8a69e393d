"""Never running stale generated code: whether a project's `generated/` is what its IDL and
parameter files make today, and making it so.

A project is a folder with `idl/*.idl` and/or compile-time parameter files (`params/*.xml`,
`services/*/*Parameters.xml`) compiled into `generated/`, as `miro new` lays it out and this
repository is:

    miro-idl -I idl idl/*.idl
    miro-params -I idl params/*.xml services/*/*Parameters.xml

`check()` answers quickly when nothing changed: it keeps the digests of the inputs (and of the
compilers that made the output) in `.miro/fresh.json`, and only when they differ compiles them
(miro_gen.compile, as those commands do, in this process) and compares. `ensure_fresh()`
regenerates what is stale, or, when `generated/` cannot be written, raises `StaleError` naming
the commands to run.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen import resources

if TYPE_CHECKING:
    from miro_gen.compile.outcome import Outcome

STAMP = Path(".miro") / "fresh.json"
_TOOL_SOURCES = ("codegen", "idl", "params/compiler")  # in miro_gen: what decides generated code


class StaleError(Exception):
    """`generated/` is stale and cannot be regenerated here; the message names the commands."""


@dataclass
class Project:
    """A project's folder and the compilers' inputs in it."""

    root: Path
    idl_files: list[Path] = field(default_factory=list)
    param_files: list[Path] = field(default_factory=list)

    @property
    def generated(self) -> Path:
        return self.root / "generated"

    def commands(self) -> list[list[str]]:
        """The compiler runs that make `generated/`, as argument lists (paths relative)."""
        out = []
        if self.idl_files:
            out.append(["miro-idl", "-I", "idl", *self._rel(self.idl_files)])
        if self.param_files:
            out.append(["miro-params", "-I", "idl", *self._rel(self.param_files)])
        return out

    def command_text(self) -> str:
        """The commands as a user types them (with the shell's patterns)."""
        out = []
        if self.idl_files:
            out.append("miro-idl -I idl idl/*.idl")
        if self.param_files:
            where = ["params/*.xml"] if (self.root / "params").is_dir() else []
            if any(p.parent.parent.name == "services" for p in self.param_files):
                where.append("services/*/*Parameters.xml")
            out.append(" ".join(["miro-params -I idl", *where]))
        return " && ".join(out)

    def _rel(self, paths: list[Path]) -> list[str]:
        return [self.relative(p) for p in paths]

    def relative(self, path: Path) -> str:
        """`path` as the commands name it, from the project's folder."""
        return path.relative_to(self.root).as_posix()


def find_project(start: Path) -> Project | None:
    """The project `start` is in (it or the nearest folder above with `generated/` beside
    `idl/`, `params/` or services' parameter files); None outside any."""
    start = start.resolve()
    for folder in (start, *start.parents):
        if not (folder / "generated").is_dir():
            continue
        params = [*(folder / "params").glob("*.xml"), *folder.glob("services/*/*Parameters.xml")]
        project = Project(folder, sorted((folder / "idl").glob("*.idl")), sorted(params))
        if project.idl_files or project.param_files:
            return project
    return None


def _digest(paths: Sequence[Path]) -> dict[str, str]:
    out = {}
    for p in paths:
        with contextlib.suppress(OSError):
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _tool_sources() -> list[Path]:
    """The folders of the generator this process runs (wherever it is installed): the IDL
    front end, the code generator, the parameter compiler, the templates, and the
    SvcParameters.xml that `miro/SvcParameters.h` includes find when a project has none."""
    folders = [resources.PACKAGE / name for name in _TOOL_SOURCES] + [resources.template_dir()]
    shipped = resources.params_dir()
    return folders if shipped is None else [*folders, shipped]


def _tool_digest() -> str:
    """One hash of the sources that decide what the compilers write: another version of
    miro-gen (an upgrade, an edited template) makes other code."""
    from miro_gen import __version__  # in the first line of every generated file

    h = hashlib.sha256(__version__.encode())
    for folder in _tool_sources():
        for p in sorted(folder.rglob("*")):
            if p.is_file() and p.suffix in (".py", ".j2", ".lark", ".xml"):
                h.update(p.relative_to(folder.parent).as_posix().encode())
                h.update(p.read_bytes())
    return h.hexdigest()


def _inputs(project: Project) -> dict[str, object]:
    idl_dir = project.root / "idl"
    includes = sorted(idl_dir.rglob("*.idl")) if idl_dir.is_dir() else []
    files = sorted({*project.idl_files, *project.param_files, *includes})
    return {
        "tool": _tool_digest(),
        "commands": project.commands(),
        "files": _digest(files),
    }


def _stamp_matches(project: Project, inputs: dict[str, object]) -> bool:
    try:
        return bool(json.loads((project.root / STAMP).read_text()) == inputs)
    except (OSError, ValueError):
        return False


def _write_stamp(project: Project, inputs: dict[str, object]) -> None:
    path = project.root / STAMP
    with contextlib.suppress(OSError):  # a read-only tree: checked in full next time
        path.parent.mkdir(exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(inputs, indent=1))
        os.replace(tmp, path)


def _compile(project: Project, check: bool) -> list[Outcome]:
    """Compile the project's IDL, then its parameter files, into `generated/` (or with `check`
    only compare): as the commands of `project.commands()` run in its folder would."""
    from miro_gen.compile.idl import idl_package
    from miro_gen.compile.params import params_package

    root = project.root
    include = [_shown(root / "idl")]
    outcomes = []
    if project.idl_files:
        files = [_shown(p) for p in project.idl_files]
        outcomes.append(
            idl_package(files, project.generated, include_dirs=include, check=check, base=root)
        )
    if project.param_files:
        files = [_shown(p) for p in project.param_files]
        outcomes.append(
            params_package(files, project.generated, include_dirs=include, check=check, base=root)
        )
    return outcomes


def _shown(path: Path) -> str:
    """An input as its problems name it: from the working folder when inside it."""
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _problems(done: Outcome) -> list[str]:
    """A compile's errors, as lines."""
    return [str(d) for d in done.diagnostics if d.severity != "warning"] + [
        f"error: {e}" for e in done.errors
    ]


@dataclass
class Freshness:
    fresh: bool
    stale: list[str] = field(default_factory=list)  # `PATH is out of date`, a line a file
    errors: list[str] = field(default_factory=list)  # compile errors (the inputs are broken)


def check(project: Project) -> Freshness:
    """Whether `generated/` is what the inputs make today."""
    inputs = _inputs(project)
    if _stamp_matches(project, inputs):
        return Freshness(True)
    stale, errors = [], []
    for done in _compile(project, check=True):
        if not done.ok:
            errors += _problems(done) or ["the compiler failed"]
        stale += [f"{project.relative(p)} is out of date" for p in done.paths()]
    if not stale and not errors:
        _write_stamp(project, inputs)
    return Freshness(not stale and not errors, stale, errors)


def ensure_fresh(project: Project) -> list[str]:
    """Regenerate `generated/` if it is stale; what was written, a line a file (`wrote
    generated/...`; empty when it was fresh). StaleError when it cannot be written, or the
    inputs do not compile (then the message holds the compilers' errors)."""
    state = check(project)
    if state.fresh:
        return []
    if state.errors:
        raise StaleError("\n".join(state.errors))
    if not os.access(project.generated, os.W_OK):
        raise StaleError(
            f"{project.generated} is out of date and cannot be written here; "
            f"run in {project.root}: {project.command_text()}"
        )
    inputs = _inputs(project)
    wrote: list[str] = []
    for done in _compile(project, check=False):
        if not done.ok:
            raise StaleError("\n".join(_problems(done)) or "the compiler failed")
        wrote += [f"wrote {project.relative(p)}" for p in done.paths()]
    _write_stamp(project, inputs)
    return wrote


def before_running(folder: Path, prog: str) -> bool:
    """What `miro run` and `miro launch` do first: regenerate the generated code of the project
    `folder` is in when it is stale (saying so on stderr); False, having said why, when it is
    stale and cannot be regenerated. True outside any project."""
    project = find_project(folder)
    if project is None:
        return True
    try:
        wrote = ensure_fresh(project)
    except StaleError as e:
        print(f"{prog}: {e}", file=sys.stderr)
        return False
    if wrote:
        print(
            f"{prog}: the IDL or parameter files changed: regenerated {len(wrote)} files in "
            f"{project.generated}",
            file=sys.stderr,
        )
    return True
