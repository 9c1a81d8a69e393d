"""Check that the code generator's output is byte-identical to that of another revision.

    python tests/codegen/compare_output.py [--base REV]

A refactoring of `miro_gen/codegen/` or `templates/idl/` must not change a byte of what
`miro-idl` writes. This script runs `miro-idl` from REV (default: where this branch left `main`)
and from the working tree on the same inputs, and compares everything they produce: the files
written, stdout, stderr and the exit status. The inputs are the IDL files of the working tree:

* `idl/*.idl` in one run (as `generated/` is made), and again one file at a time into one folder
  (package `__init__`s then list modules written by earlier runs);
* `tests/codegen/*.idl` (the golden output), each file of `tests/codegen/refused/`,
  `tests/rpc/*.idl`, `tests/foxglove/*.idl`;
* every file of the IDL corpus (`tests/corpus/`), valid or not, each on its own;
* a large generated file (`bench/gen_idl.py`, 40 modules).

Both revisions run in-process, one interpreter each, from the repository root (so that the
`# Source:` lines read the same). Exit status 0 when identical; otherwise the differences are
listed (unified diffs of the first few files) and the status is 1.
"""

from __future__ import annotations

import argparse
import difflib
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

# Runs in a fresh interpreter with the code under test first on sys.path: each job is
# (name, arguments of miro-idl, output folder or "" for arguments that name it themselves).
DRIVER = r"""
import contextlib, io, json, sys
code, jobs_file, results_file = sys.argv[1:4]
sys.path.insert(0, code)
from miro_gen.cli.idl import main
results = {}
for name, args in json.load(open(jobs_file)):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(args)
        except SystemExit as e:
            rc = e.code
    results[name] = [rc, out.getvalue(), err.getvalue()]
json.dump(results, open(results_file, "w"))
"""


def rel(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


def jobs(out: Path) -> list[tuple[str, list[str]]]:
    """(name, miro-idl arguments) of every run; each writes under out/name."""
    found: list[tuple[str, list[str]]] = []
    idl = sorted(rel(p) for p in (REPO / "idl").glob("*.idl"))
    found.append(("generated", ["-I", "idl", "-o", str(out / "generated"), *idl]))
    for f in idl:  # one at a time into one folder: later runs see earlier modules on disk
        found.append((f"incremental:{f}", ["-I", "idl", "-o", str(out / "incremental"), f]))
    golden = sorted(rel(p) for p in (REPO / "tests" / "codegen").glob("*.idl"))
    found.append(("golden", ["-I", "tests/codegen", "-o", str(out / "golden"), *golden]))
    singles = [
        *sorted((REPO / "tests" / "codegen" / "refused").glob("*.idl")),
        *sorted((REPO / "tests" / "rpc").glob("*.idl")),
        *sorted((REPO / "tests" / "foxglove").glob("*.idl")),
        *sorted((REPO / "tests" / "corpus").rglob("*.idl")),
        out / "big.idl",
    ]
    include = ["-I", "tests/corpus/include", "-I", "idl"]
    for i, p in enumerate(singles):
        name = rel(p) if p.is_relative_to(REPO) else p.name
        found.append((name, [*include, "-o", str(out / f"single{i}"), str(p)]))
    return found


def run(code: Path, out: Path, work: Path) -> dict[str, list[object]]:
    """Every job with the miro_gen in `code`; results by job name, files under `out`."""
    out.mkdir(parents=True)
    sys.path.insert(0, str(REPO / "bench"))
    from gen_idl import module

    (out / "big.idl").write_text("".join(module(i) for i in range(40)))
    jobs_file = work / f"jobs-{out.name}.json"
    results_file = work / f"results-{out.name}.json"
    jobs_file.write_text(json.dumps(jobs(out)))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    subprocess.run(
        [sys.executable, "-P", "-c", DRIVER, str(code), str(jobs_file), str(results_file)],
        cwd=REPO,
        env=env,
        check=True,
    )
    results: dict[str, list[object]] = json.loads(results_file.read_text())
    for value in results.values():  # the output folder's name differs between the two runs
        value[1:] = [str(v).replace(str(out), "OUT") for v in value[1:]]
    return results


def files(root: Path) -> dict[str, bytes]:
    return {
        p.relative_to(root).as_posix(): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and "__pycache__" not in p.parts
    }


def base_revision() -> str:
    return subprocess.run(
        ["git", "merge-base", "HEAD", "main"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.strip()


def export(rev: str, dest: Path) -> None:
    """miro_gen/ and templates/ of `rev` into `dest`."""
    archive = subprocess.run(
        ["git", "archive", rev, "miro_gen", "templates"], cwd=REPO, capture_output=True, check=True
    ).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(dest, filter="tar")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", help="revision to compare with (default: merge base with main)")
    args = ap.parse_args()
    rev = args.base or base_revision()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        export(rev, work / "base-code")
        before = run(work / "base-code", work / "base", work)
        after = run(REPO, work / "head", work)
        problems: list[str] = []
        for name in sorted(set(before) | set(after)):
            if before.get(name) != after.get(name):
                problems.append(f"{name}: exit status or messages differ")
                problems.append(f"  base: {before.get(name)!r}")
                problems.append(f"  head: {after.get(name)!r}")
        old, new = files(work / "base"), files(work / "head")
        diffs = 0
        for path in sorted(set(old) | set(new)):
            if old.get(path) == new.get(path):
                continue
            problems.append(f"{path}: differs")
            if diffs < 5:
                a = old.get(path, b"").decode(errors="replace").splitlines(keepends=True)
                b = new.get(path, b"").decode(errors="replace").splitlines(keepends=True)
                problems += [
                    line.rstrip("\n") for line in difflib.unified_diff(a, b, "base", "head", n=2)
                ]
            diffs += 1
        if problems:
            print("\n".join(problems))
            print(f"compare_output: {diffs} of {len(old)} files differ from {rev[:12]}")
            return 1
        print(f"compare_output: {len(old)} files and {len(before)} runs identical to {rev[:12]}")
        return 0


if __name__ == "__main__":
    sys.exit(main())
