"""Benchmark: `miro-idl --ast-json` against `omniidl -bdump`, whole processes, same run.

    python bench/bench_idl.py [--modules N] [--repeat R] [--check]

Generates an IDL file of about 10,000 lines (218 modules of structs, typedefs, constants, unions,
exceptions and interfaces; see gen_idl.py), runs both compilers on it R times, interleaved, and
prints the medians and their ratio; then times both on a tiny file (the manual's Example.idl).
Targets (issue "IDL front end"): ratio at most 2.0 on the large file, under 0.3 s on tiny files.
`--check` exits 1 when a target is missed.

Both are measured as a user runs them: the installed `miro-idl` script (bytecode compiled and the
grammar tables cached by a warm-up run, as after `pip install`) and Debian's `omniidl`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from gen_idl import module  # noqa: E402

RATIO_TARGET = 2.0
TINY_TARGET_S = 0.3


def miro_idl_command() -> list[str]:
    """The console script next to this interpreter, else `python -m` (never a pyenv shim)."""
    script = Path(sys.executable).with_name("miro-idl")
    if script.exists():
        return [str(script)]
    return [sys.executable, "-m", "miro_gen.cli.idl"]


def run_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # measure with bytecode caching, as installed
    return env


def time_once(cmd: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr.decode(errors='replace')}")
    return elapsed


def measure(cmds: dict[str, list[str]], repeat: int, env: dict[str, str]) -> dict[str, list[float]]:
    times: dict[str, list[float]] = {name: [] for name in cmds}
    for _ in range(repeat):
        for name, cmd in cmds.items():  # interleaved, so drift affects both alike
            times[name].append(time_once(cmd, env))
    return times


OURS = "miro-idl --ast-json"
THEIRS = "omniidl -bdump"


def compare(
    title: str,
    idl: Path,
    ours: list[str],
    omniidl: str | None,
    repeat: int,
    env: dict[str, str],
) -> dict[str, list[float]]:
    """Time both compilers on `idl` and print a table; returns the times by command."""
    cmds = {OURS: [*ours, "--ast-json", str(idl)]}
    if omniidl:
        cmds[THEIRS] = [omniidl, "-bdump", str(idl)]
    times = measure(cmds, repeat, env)
    print()
    print(f"{title:24} {'median s':>9} {'min s':>8}")
    for name, ts in times.items():
        print(f"{name:24} {statistics.median(ts):9.3f} {min(ts):8.3f}")
    return times


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--modules", type=int, default=218, help="modules in the large file (218)")
    ap.add_argument("--repeat", type=int, default=9, help="runs of each command (9)")
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    args = ap.parse_args()

    env = run_env()
    ours = miro_idl_command()
    omniidl = shutil.which("omniidl")
    tiny = ROOT / "idl" / "Example.idl"
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        big = Path(tmp) / "big.idl"
        big.write_text("".join(module(i) for i in range(args.modules)))
        lines = big.read_text().count("\n")
        print(f"large file: {lines} lines, {args.modules} modules; {args.repeat} runs each")
        print(f"miro-idl:   {' '.join(ours)}")
        print(f"omniidl:    {omniidl or 'not installed (apt-get install omniidl)'}")

        time_once([*ours, "--ast-json", str(big)], env)  # warm-up: bytecode and grammar cache
        times = compare("large file", big, ours, omniidl, args.repeat, env)
        if omniidl:
            ratio = statistics.median(times[OURS]) / statistics.median(times[THEIRS])
            verdict = "ok" if ratio <= RATIO_TARGET else "MISSED"
            print(f"ratio miro-idl / omniidl: {ratio:.2f} (target <= {RATIO_TARGET}: {verdict})")
            ok &= ratio <= RATIO_TARGET

        tiny_median = statistics.median(
            compare("tiny file (Example.idl)", tiny, ours, omniidl, args.repeat, env)[OURS]
        )
        verdict = "ok" if tiny_median < TINY_TARGET_S else "MISSED"
        print(
            f"miro-idl on a tiny file: {tiny_median:.3f} s (target < {TINY_TARGET_S} s: {verdict})"
        )
        ok &= tiny_median < TINY_TARGET_S
    return 0 if ok or not args.check else 1


if __name__ == "__main__":
    sys.exit(main())
