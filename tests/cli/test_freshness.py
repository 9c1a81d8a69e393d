"""The freshness check's fast path (miro_gen.cli.freshness): a project whose files all have the
stats they were hashed with is fresh without reading or hashing anything, and an edit is found
even when it keeps the file's size and puts its mtime back."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from miro_cli import REPO
from test_build import make_project

from miro_gen.cli import freshness as proj


def settled_now(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every file counts as settled (as if the check ran a minute after the last edit)."""
    monkeypatch.setattr(proj, "SETTLE_NS", -60_000_000_000)


def edit_keeping_size_and_mtime(path: Path, old: bytes, new: bytes) -> None:
    """Replace `old` by `new` (as long) in `path` and put its mtime back: only the ctime (which
    no one can set) shows the edit. Repeated until the ctime moved on, since the file system's
    clock ticks in milliseconds."""
    assert len(old) == len(new)
    before = path.stat()
    text = path.read_bytes()
    assert old in text
    for _ in range(2000):
        path.write_bytes(text.replace(old, new))
        os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
        if path.stat().st_ctime_ns != before.st_ctime_ns:
            break
        time.sleep(0.001)
    after = path.stat()
    assert (after.st_size, after.st_mtime_ns) == (before.st_size, before.st_mtime_ns)


def stamp(root: Path) -> dict[str, object]:
    loaded = json.loads((root / proj.STAMP).read_text())
    assert isinstance(loaded, dict)
    return loaded


def test_an_edit_that_keeps_size_and_mtime_still_rebuilds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    settled_now(monkeypatch)
    root = make_project(tmp_path)
    project = proj.find_project(root)
    assert project is not None
    proj.ensure_fresh(project)
    assert "stats" in stamp(root)  # the fast path is armed
    assert proj.check(project).fresh
    xml = root / "services" / "arm" / "ArmParameters.xml"
    edit_keeping_size_and_mtime(xml, b'default="1.5"', b'default="2.5"')
    state = proj.check(project)
    assert not state.fresh
    assert state.stale == ["generated/Arm/ArmParameters.py is out of date"]
    assert proj.ensure_fresh(project) == ["wrote generated/Arm/ArmParameters.py"]
    assert "default=2.5" in (root / "generated" / "Arm" / "ArmParameters.py").read_text()
    assert proj.check(project).fresh


def test_files_changed_just_before_the_check_are_hashed_every_time(tmp_path: Path) -> None:
    """A file written in the same clock tick as the check may keep its stats through another
    edit: the stats of files that have not settled are not kept, so they are hashed again
    (here the edit is seen even where the ctime did not move)."""
    root = make_project(tmp_path)
    project = proj.find_project(root)
    assert project is not None
    proj.ensure_fresh(project)
    assert "stats" not in stamp(root)  # written a moment ago: not settled
    idl = root / "idl" / "Example.idl"
    before = idl.stat()
    text = idl.read_bytes()
    idl.write_bytes(text.replace(b"getData", b"getDatb"))
    os.utime(idl, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert not proj.check(project).fresh


def test_touched_files_are_hashed_once_then_trusted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A new mtime with the same contents (a `touch`, a checkout) is fresh, and the stamp takes
    the new stats, so that the next check reads nothing again."""
    settled_now(monkeypatch)
    root = make_project(tmp_path)
    project = proj.find_project(root)
    assert project is not None
    proj.ensure_fresh(project)
    idl = root / "idl" / "Example.idl"
    os.utime(idl, ns=(idl.stat().st_atime_ns, idl.stat().st_mtime_ns + 10**9))
    stats = stamp(root)["stats"]
    assert proj.check(project).fresh
    assert stamp(root)["stats"] != stats
    assert isinstance(stats, dict) and str(idl) in stats


def test_new_and_removed_inputs_are_seen(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    settled_now(monkeypatch)
    root = make_project(tmp_path)
    project = proj.find_project(root)
    assert project is not None
    proj.ensure_fresh(project)
    extra = root / "idl" / "Extra.idl"
    extra.write_text("module Extra { struct S { long x; }; };\n")
    project = proj.find_project(root)
    assert project is not None
    assert not proj.check(project).fresh
    proj.ensure_fresh(project)
    assert (root / "generated" / "Extra").is_dir()
    assert str(extra) in stamp(root)["files"]  # type: ignore[operator]
    extra.unlink()  # compiled again (nothing of the rest changes), and the stamp follows
    project = proj.find_project(root)
    assert project is not None
    assert proj.check(project).fresh
    assert str(extra) not in stamp(root)["files"]  # type: ignore[operator]


def test_a_fresh_check_imports_no_hashing(tmp_path: Path) -> None:
    """With every file settled and unchanged, the check reads no input and imports no hashlib
    (its OpenSSL: megabytes and milliseconds of every `miro run`)."""
    root = make_project(tmp_path)
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "from miro_gen.cli import freshness as f\n"
        "f.SETTLE_NS = -60_000_000_000\n"
        f"p = f.find_project(Path({str(root)!r}))\n"
        "if sys.argv[1] == 'build':\n"
        "    f.ensure_fresh(p)\n"
        "print(f.check(p).fresh, 'hashlib' in sys.modules)\n"
    )

    def run(what: str) -> str:
        env = dict(os.environ, PYTHONPATH=str(REPO))
        done = subprocess.run(
            [sys.executable, "-c", code, what], env=env, capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    assert run("build") == "True True"  # compiled: hashed
    assert run("check") == "True False"
