"""The output folder: which generated files differ from what is there, and writing them so
that an error leaves the folder as it was.

Every changed file is first written to a temporary file beside its place (`.NAME.PID.tmp`);
only when all of them are written are they renamed into place, in order. A folder that did not
exist gets its files under their own names at once (nothing was there to keep); a folder made
for them is removed again, with them, if the run fails.

`update` renders and writes the files of a large run in several processes: rendering is
Python (one core per process), and making a file or a folder is mostly waiting for the file
system (milliseconds each on a busy disk), which other processes' work, and other threads'
waits, overlap. Each process (forked, so that it shares the contexts already built) renders
a share of the files, then writes those that changed to temporary files with several
threads; the parent renames them once all have succeeded. Small runs, and systems without
`fork`, stay in one process.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Generic, TypeVar

T = TypeVar("T")

PARALLEL_FROM = 64  # files; fewer are rendered and written by this process alone
MAX_PROCESSES = 4
WRITERS = 8  # threads of a process writing files, when it writes many folders


@dataclass
class _Staged:
    """What one process did: the files that differ, their temporary files, the folders made;
    and, when it failed, why (`error` re-raised in the parent, or `failure` text)."""

    changed: list[str] = field(default_factory=list)
    temporary: dict[str, str] = field(default_factory=dict)  # rel -> its temporary file
    in_place: list[str] = field(default_factory=list)  # files written in folders that were new
    made: list[str] = field(default_factory=list)
    error: OSError | None = None
    failure: str = ""


@dataclass
class _Share(Generic[T]):
    """A process's share of the files: (relative path, what renders it)."""

    items: Sequence[tuple[str, T]]
    render: Callable[[T], str]


def changed_files(files: dict[str, str], outdir: Path) -> list[str]:
    """The relative paths whose content on disk differs (or that do not exist)."""
    share = _Share(sorted(files.items()), _identity)
    return _stage(share, str(outdir), write=False).changed


def write_files(files: dict[str, str], rels: list[str], outdir: Path) -> None:
    """Write `rels` of `files` under `outdir`: all to temporary files first, then renamed."""
    share = _Share([(rel, files[rel]) for rel in rels], _identity)
    staged = _stage(share, str(outdir), write=True, compare=False)
    _commit(rels, [staged], str(outdir))


def update(
    items: Sequence[tuple[str, T]],
    render: Callable[[T], str],
    outdir: Path,
    *,
    check: bool,
    weight: Callable[[T], int] = lambda _: 1,
) -> list[str]:
    """Render each (relative path, context) with `render` and compare it with `outdir`; unless
    `check`, write those that differ. Returns the relative paths that differ, sorted. OSError
    when a file cannot be written (nothing is then changed). `weight` estimates what rendering
    a context costs, so that the processes get shares of equal work."""
    out = str(outdir)
    processes = _processes(len(items))
    if processes == 1:
        staged = [_stage(_Share(items, render), out, write=not check)]
    else:
        shares = [_Share(share, render) for share in _shares(items, processes, weight)]
        staged = _in_processes(shares, out, write=not check)
    changed = sorted(rel for s in staged for rel in s.changed)
    if not check:
        _commit(changed, staged, out)
    return changed


def _identity(text: str) -> str:
    return text


def _processes(files: int) -> int:
    """How many processes share `files` files: one for few files, where there is no fork, and
    in a process with other threads (a forked child holds no thread but the caller's, and so
    none of the locks they may hold)."""
    if files < PARALLEL_FROM or not hasattr(os, "fork") or not sys.platform.startswith("linux"):
        return 1
    if threading.active_count() > 1:
        return 1
    return max(1, min(MAX_PROCESSES, len(os.sched_getaffinity(0))))


def _shares(
    items: Sequence[tuple[str, T]], count: int, weight: Callable[[T], int]
) -> list[list[tuple[str, T]]]:
    """`items` in `count` shares of about equal weight (the heaviest first, each to the share
    that has least so far), each in the order of `items`."""
    loads = [0] * count
    chosen: list[list[int]] = [[] for _ in range(count)]
    for i in sorted(range(len(items)), key=lambda i: -weight(items[i][1])):
        least = loads.index(min(loads))
        loads[least] += weight(items[i][1])
        chosen[least].append(i)
    return [[items[i] for i in sorted(share)] for share in chosen]


def _stage(share: _Share[T], outdir: str, *, write: bool, compare: bool = True) -> _Staged:
    """Render the share's files; note those that differ from the folder's (each folder is
    listed once) and, with `write`, write them to temporary files. An OSError is recorded in
    the result, with what was made until then (the caller removes it); anything else removes
    what was made and propagates."""
    staged = _Staged()
    listings: dict[str, frozenset[str] | None] = {}
    folders: dict[str, list[tuple[str, str, str]]] = {}  # folder -> (rel, name, content)
    try:
        for rel, source in share.items:
            content = share.render(source)
            path = os.path.join(outdir, rel)
            folder, name = os.path.split(path)
            if compare and _same(path, name, content, _listing(folder, listings)):
                continue
            staged.changed.append(rel)
            if write:
                folders.setdefault(folder, []).append((rel, name, content))
        new = {folder for folder in folders if compare and listings[folder] is None}
        _write(folders, new, staged)
    except OSError as e:
        staged.error = e
    except BaseException:
        _discard([staged], set())
        raise
    return staged


def _write(folders: dict[str, list[tuple[str, str, str]]], new: set[str], staged: _Staged) -> None:
    """Make each folder and write its files, to temporary files but in the folders that did
    not exist (`new`); many folders at once by several threads (once this process renders no
    more: they would wait for it)."""
    suffix = f".{os.getpid()}.tmp"

    def write(folder: str, files: list[tuple[str, str, str]]) -> None:
        _make_folder(folder, staged.made)
        for rel, name, content in files:
            if folder in new:
                path = os.path.join(folder, name)
                with open(path, "w", encoding="utf-8") as fh:
                    staged.in_place.append(path)
                    fh.write(content)
                continue
            tmp = os.path.join(folder, f".{name}{suffix}")
            with open(tmp, "w", encoding="utf-8") as fh:
                staged.temporary[rel] = tmp
                fh.write(content)

    if len(folders) < 2 * WRITERS:
        for folder, files in folders.items():
            write(folder, files)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(WRITERS) as pool:
        for done in [pool.submit(write, folder, files) for folder, files in folders.items()]:
            done.result()  # the first error, once every thread has stopped


def _listing(folder: str, listings: dict[str, frozenset[str] | None]) -> frozenset[str] | None:
    """The names in `folder` (looked up once); None when there is no such folder."""
    if folder not in listings:
        try:
            listings[folder] = frozenset(os.listdir(folder))
        except FileNotFoundError:
            listings[folder] = None
        except OSError:
            listings[folder] = frozenset()
    return listings[folder]


def _same(path: str, name: str, content: str, names: frozenset[str] | None) -> bool:
    if names is None or name not in names:
        return False
    try:
        with open(path, encoding="utf-8") as fh:
            return fh.read() == content
    except (OSError, UnicodeDecodeError):
        return False


def _make_folder(folder: str, made: list[str]) -> None:
    """`os.makedirs`, noting each folder it makes (another process may make one first)."""
    if os.path.isdir(folder):
        return
    parent = os.path.dirname(folder)
    if parent and parent != folder:
        _make_folder(parent, made)
    try:
        os.mkdir(folder)
    except FileExistsError:
        if not os.path.isdir(folder):
            raise
        return
    made.append(folder)


def _in_processes(shares: list[_Share[T]], outdir: str, *, write: bool) -> list[_Staged]:
    """Stage the first share here and each other one in a forked process (here too when a
    process cannot be started)."""
    children: list[tuple[int, int]] = []
    staged: list[_Staged] = []
    try:
        for share in shares[1:]:
            try:
                children.append(_fork(share, outdir, write))
            except OSError:  # no process to be had: do it here
                staged.append(_stage(share, outdir, write=write))
        staged.append(_stage(shares[0], outdir, write=write))
    except BaseException:
        _discard([*staged, *(_collect(pid, fd) for pid, fd in children)], set())
        raise
    return [*staged, *(_collect(pid, fd) for pid, fd in children)]


def _fork(share: _Share[T], outdir: str, write: bool) -> tuple[int, int]:
    read, send = os.pipe()
    try:
        pid = os.fork()
    except OSError:
        os.close(read)
        os.close(send)
        raise
    if pid == 0:  # the child: stage its share, send what it did, and end here
        os.close(read)
        try:
            result = _stage(share, outdir, write=write)
        except BaseException:  # a defect, or Ctrl-C: said in the parent
            result = _Staged(failure=traceback.format_exc())
        try:
            with os.fdopen(send, "wb") as pipe:
                pipe.write(pickle.dumps(result))
        finally:
            os._exit(0)
    os.close(send)
    return pid, read


def _collect(pid: int, fd: int) -> _Staged:
    with os.fdopen(fd, "rb") as pipe:
        data = pipe.read()
    _, status = os.waitpid(pid, 0)
    try:
        result: _Staged = pickle.loads(data)
    except Exception:
        result = _Staged(failure=f"a process writing generated files ended (status {status})")
    return result


def _commit(rels: Sequence[str], staged: list[_Staged], outdir: str) -> None:
    """Rename the temporary files into place, in the order of `rels`; on any error (of a
    process, or of a rename) remove the temporary files left and the folders made."""
    temporary = {rel: tmp for s in staged for rel, tmp in s.temporary.items()}
    renamed: set[str] = set()
    try:
        for s in staged:
            if s.failure:
                raise RuntimeError(f"writing generated files failed:\n{s.failure}")
            if s.error is not None:
                raise s.error
        for rel in rels:
            if rel in temporary:
                os.replace(temporary[rel], os.path.join(outdir, rel))
                renamed.add(rel)
    except BaseException:
        _discard(staged, renamed)
        raise


def _discard(staged: list[_Staged], renamed: set[str]) -> None:
    """Remove the temporary files (but those `renamed`), the files written in new folders, and
    then the folders made, if empty."""
    for s in staged:
        left = [tmp for rel, tmp in s.temporary.items() if rel not in renamed]
        for path in [*left, *s.in_place]:
            with contextlib.suppress(OSError):
                os.unlink(path)
    for folder in sorted((f for s in staged for f in s.made), key=len, reverse=True):
        with contextlib.suppress(OSError):
            os.rmdir(folder)  # only if empty: a failed rename leaves files in it
