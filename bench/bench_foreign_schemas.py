"""Benchmark: how long `miro call` and `miro list` take to refuse a hostile service's schemas
(issue 25), and what compiling a service's schema in a process of its own costs.

    python bench/bench_foreign_schemas.py [--repeat 5] [--baseline DIR]

A naming service, a service whose objects give hostile interface schemas (tests/procs/
hostile_schemas.py: `#include "FILE"`, and 10 MB of IDL; both with --max-message-size 64M, so
that the 10 MB reach the tool) and ExampleA (tests/procs/named_example.py) run on loopback.
Each case is the tool run as a user runs it, start-up included:

* `call Include`: `miro call robot/Include getData`, refused (directives);
* `call Huge`: the same on the 10 MB schema, refused (size);
* `list`: `miro list`, which meets both;
* `call ExampleA, cached`: a normal call whose schema was compiled before (the reference);
* `call ExampleA, compiled`: the same with an empty schema cache: the schema is compiled
  (`python -m miro_gen.compile`, in a process of its own).

The cases run interleaved, `--repeat` times; printed: the median seconds, their spread, the
ratio to the reference, and the load average. `--baseline DIR` runs the same tools from another
source tree (`git archive <before> | tar -x -C DIR`), once per case and at most 30 s each.
Target (issue 25): each refusal within a second.

`--scan` times, in this process, the look for directives on text built against it (1 MiB of
comments left open, of quotes), against the pattern used before (`re.sub` of comments and
literals, which rescans the rest of the text from every `/*` left open) on a tenth of it.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 1.0
ROOMY = ["--max-message-size", "64M"]


def env_for(tree: Path, **extra: str) -> dict[str, str]:
    env = dict(os.environ, MIRO_DISCOVERY="0", **extra)
    env["PYTHONPATH"] = os.pathsep.join([str(tree / "generated"), str(tree)])
    return env


def start(args: list[str], ready: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env_for(ROOT)
    )
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line.startswith(ready), line
    return proc


def cases(naming: str) -> dict[str, tuple[list[str], bool]]:
    """name -> (miro's arguments, whether the schema cache starts empty)."""
    common = ["--naming", naming]
    return {
        "call Include (refused)": (["call", "robot/Include", "getData", *common], False),
        "call Huge, 10 MB (refused)": (["call", "robot/Huge", "getData", *common, *ROOMY], False),
        "list (both refused)": (["list", *common, *ROOMY], False),
        "call ExampleA, cached": (["call", "robot/ExampleA", "getData", *common], False),
        "call ExampleA, compiled": (["call", "robot/ExampleA", "getData", *common], True),
    }


def run(tree: Path, args: list[str], cache: Path, fresh: bool, timeout: float) -> float | None:
    if fresh:
        shutil.rmtree(cache, ignore_errors=True)
    t0 = time.perf_counter()
    try:
        subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *args],
            capture_output=True,
            cwd=cache.parent,  # not a source tree: `python -m` puts the working folder first
            env=env_for(tree, MIRO_CACHE=str(cache)),
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return None
    return time.perf_counter() - t0


# The look for directives before issue 25 (eventlog/types.py at b5e51cb), for --scan.
_BEFORE = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'', re.S)


def scan(repeat: int) -> None:
    from miro_gen.compile.foreign import MAX_SCHEMA_BYTES, refusal

    n = MAX_SCHEMA_BYTES - 1  # and a `#`, so that the text is looked through
    texts = {"open comments": "/* " * (n // 3) + "#", "quotes": '"' * n + "#"}
    head = f"{'look for directives':26} {'1 MiB, ours s':>14} {'spread s':>11}"
    print(f"{head} {'1/10 MiB, before s':>19}")
    for name, text in texts.items():
        ours, before = [], []
        for _ in range(repeat):
            t0 = time.perf_counter()
            assert refusal(text) is None, name
            ours.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            _BEFORE.sub(" ", text[: len(text) // 10])
            before.append(time.perf_counter() - t0)
        spread = f"{min(ours):.3f}-{max(ours):.3f}"
        row = f"{name:26} {statistics.median(ours):14.3f} {spread:>11}"
        print(f"{row} {statistics.median(before):19.3f}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--baseline", type=Path, help="another source tree to run once per case")
    p.add_argument("--scan", action="store_true", help="also time the look for directives")
    ns = p.parse_args()
    if ns.scan:
        scan(ns.repeat)
    folder = Path(tempfile.mkdtemp(prefix="bench-foreign-"))
    secret = folder / "secret.idl"
    secret.write_text("secret_content_of_the_file;\n")
    naming = f"tcp://127.0.0.1:{free_port()}"
    procs = [
        start(
            [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint", naming],
            "naming service at",
        )
    ]
    try:
        service = ["--naming", naming, "-MNC", "robot"]
        hostile = ROOT / "tests" / "procs" / "hostile_schemas.py"
        procs.append(start([sys.executable, str(hostile), str(secret), *service, *ROOMY], "READY"))
        example = ROOT / "tests" / "procs" / "named_example.py"
        procs.append(start([sys.executable, str(example), *service], "READY"))
        table = cases(naming)
        times: dict[str, list[float]] = {name: [] for name in table}
        cache = folder / "cache"
        run(ROOT, table["call ExampleA, cached"][0], cache, True, 60)  # fills the cache
        for _ in range(ns.repeat):
            for name, (args, fresh) in table.items():
                took = run(ROOT, args, folder / ("fresh" if fresh else "cache"), fresh, 60)
                assert took is not None, name
                times[name].append(took)
        before: dict[str, float | None] = {}
        if ns.baseline is not None:
            old_cache = folder / "old-cache"
            run(ns.baseline, table["call ExampleA, cached"][0], old_cache, True, 60)
            for name, (args, fresh) in table.items():
                where = folder / ("old-fresh" if fresh else "old-cache")
                before[name] = run(ns.baseline, args, where, fresh, 30)
    finally:
        for proc in reversed(procs):
            proc.terminate()
            proc.wait(timeout=30)
        shutil.rmtree(folder, ignore_errors=True)
    reference = statistics.median(times["call ExampleA, cached"])
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    head = f"{'case':32} {'median s':>9} {'spread s':>13} {'/ cached call':>13}"
    print(head + (f" {'baseline s':>11}" if before else ""))
    missed = []
    for name, seconds in times.items():
        median = statistics.median(seconds)
        spread = f"{min(seconds):.2f}-{max(seconds):.2f}"
        row = f"{name:32} {median:9.2f} {spread:>13} {median / reference:12.2f}x"
        if before:
            old = before[name]
            row += f" {'> 30' if old is None else f'{old:.2f}':>11}"
        print(row)
        if "refused" in name and median > TARGET_S:
            missed.append(name)
    print(
        f"target: each refusal within {TARGET_S:g} s: "
        + ("met" if not missed else f"missed: {missed}")
    )
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
