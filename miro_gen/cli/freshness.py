"""Never running stale generated code: whether a project's `generated/` is what its IDL and
parameter files make today, and making it so.

A project is a folder with `idl/*.idl` and/or compile-time parameter files (`params/*.xml`,
`services/*/*Parameters.xml`) compiled into `generated/`, as `miro new` lays it out and this
repository is:

    miro-idl -I idl idl/*.idl
    miro-params -I idl params/*.xml services/*/*Parameters.xml

`check()` answers quickly when nothing changed: it keeps the digests of the inputs (and of the
compilers that made the output) in `.miro/fresh.json`, and only when they differ compiles them
(miro_gen.compile, as those commands do, in this process) and compares. Beside the digests it
keeps each file's size, mtime, ctime and inode as they were when it was hashed: when every file
still has them, nothing is read or hashed (a service's start without hashlib's OpenSSL). Any
edit changes the ctime, which no one can set back (an edit that restores the mtime, `cp -p`,
`touch -d`); a file changed within the file system's clock tick of being hashed could keep it,
so the stat is kept only for files settled `SETTLE_NS` before (until then they are hashed).
`ensure_fresh()` regenerates what is stale, or, when `generated/` cannot be written, raises
`StaleError` naming the commands to run."""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from miro_gen import resources

if TYPE_CHECKING:
    from miro_gen.compile.outcome import Outcome

STAMP = Path(".miro") / "fresh.json"
_TOOL_SOURCES = ("codegen", "idl", "params/compiler")  # in miro_gen: what decides generated code
_TOOL_SUFFIXES = (".py", ".j2", ".lark", ".xml")
SETTLE_NS = 2_000_000_000  # a file's stat is trusted once it is this much older than the check


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
    import hashlib  # here: a check whose stats all match hashes nothing

    out = {}
    for p in paths:
        with contextlib.suppress(OSError):
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


Stats = dict[str, list[int]]  # a file's path -> [size, mtime_ns, ctime_ns, inode]


def _stats(paths: Sequence[Path]) -> Stats:
    """What the file system says of each file (a missing one is left out)."""
    out = {}
    for p in paths:
        with contextlib.suppress(OSError):
            st = os.stat(p)
            out[str(p)] = [st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino]
    return out


def _settled(stats: Stats, now_ns: int) -> bool:
    """Whether every file was last changed `SETTLE_NS` before `now_ns`: a later change would
    then show in its ctime (one changed in the same clock tick as its stat might not)."""
    return all(max(mtime, ctime) < now_ns - SETTLE_NS for _, mtime, ctime, _ in stats.values())


def _tool_sources() -> list[Path]:
    """The folders of the generator this process runs (wherever it is installed): the IDL
    front end, the code generator, the parameter compiler, the templates, and the
    SvcParameters.xml that `miro/SvcParameters.h` includes find when a project has none."""
    folders = [resources.PACKAGE / name for name in _TOOL_SOURCES] + [resources.template_dir()]
    shipped = resources.params_dir()
    return folders if shipped is None else [*folders, shipped]


def _tool_files() -> list[Path]:
    """The files of `_tool_sources()` whose contents decide the generated code, in order."""
    return [
        p
        for folder in _tool_sources()
        for p in sorted(folder.rglob("*"))
        if p.suffix in _TOOL_SUFFIXES and p.is_file()
    ]


def _tool_digest(files: Sequence[Path]) -> str:
    """One hash of the sources that decide what the compilers write: another version of
    miro-gen (an upgrade, an edited template) makes other code."""
    import hashlib

    from miro_gen import __version__  # in the first line of every generated file

    h = hashlib.sha256(__version__.encode())
    for folder in _tool_sources():
        for p in files:
            if p.is_relative_to(folder):
                h.update(p.relative_to(folder.parent).as_posix().encode())
                h.update(p.read_bytes())
    return h.hexdigest()


def _input_files(project: Project) -> list[Path]:
    idl_dir = project.root / "idl"
    includes = sorted(idl_dir.rglob("*.idl")) if idl_dir.is_dir() else []
    return sorted({*project.idl_files, *project.param_files, *includes})


def _inputs(project: Project, tool_files: Sequence[Path]) -> dict[str, object]:
    """The digests that decide whether `generated/` is fresh (what the stamp records)."""
    return {
        "tool": _tool_digest(tool_files),
        "commands": project.commands(),
        "files": _digest(_input_files(project)),
    }


def _all_stats(project: Project, tool_files: Sequence[Path]) -> Stats:
    """The stats of every file the digests cover, and of the file that holds miro-gen's
    version (which the tool's digest includes)."""
    version = resources.PACKAGE / "__init__.py"
    return _stats([version, *tool_files, *_input_files(project)])


def _read_stamp(project: Project) -> dict[str, object] | None:
    try:
        stamp = json.loads((project.root / STAMP).read_text())
    except (OSError, ValueError):
        return None
    return stamp if isinstance(stamp, dict) else None


def _digests(stamp: dict[str, object] | None) -> dict[str, object] | None:
    """What a stamp says of the inputs' digests (without the files' stats)."""
    if stamp is None:
        return None
    return {k: v for k, v in stamp.items() if k != "stats"}


def _write_stamp(project: Project, inputs: dict[str, object], stats: Stats, now_ns: int) -> None:
    """Record the digests, and the stats they were taken with if every file has settled."""
    stamp = dict(inputs, stats=stats) if _settled(stats, now_ns) else inputs
    path = project.root / STAMP
    with contextlib.suppress(OSError):  # a read-only tree: checked in full next time
        path.parent.mkdir(exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(stamp, indent=1))
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
    now_ns = time.time_ns()  # before the stats: a change after them is newer than this
    tool_files = _tool_files()
    stats = _all_stats(project, tool_files)  # before reading: a later change shows next time
    stamp = _read_stamp(project)
    if (
        stamp is not None
        and stamp.get("stats") == stats
        and stamp.get("commands") == project.commands()
    ):
        return Freshness(True)  # every file as it was when hashed: nothing read
    inputs = _inputs(project, tool_files)
    if _digests(stamp) == inputs:
        if stamp is not None and stamp.get("stats") != stats:
            _write_stamp(project, inputs, stats, now_ns)  # touched, or settled since
        return Freshness(True)
    stale, errors = [], []
    for done in _compile(project, check=True):
        if not done.ok:
            errors += _problems(done) or ["the compiler failed"]
        stale += [f"{project.relative(p)} is out of date" for p in done.paths()]
    if not stale and not errors:
        _write_stamp(project, inputs, stats, now_ns)
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
    now_ns = time.time_ns()
    tool_files = _tool_files()
    stats = _all_stats(project, tool_files)
    inputs = _inputs(project, tool_files)
    wrote: list[str] = []
    for done in _compile(project, check=False):
        if not done.ok:
            raise StaleError("\n".join(_problems(done)) or "the compiler failed")
        wrote += [f"wrote {project.relative(p)}" for p in done.paths()]
    _write_stamp(project, inputs, stats, now_ns)
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
