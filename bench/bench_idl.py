"""Benchmark: `miro-idl` against omniidl, whole processes, same run, interleaved.

    python bench/bench_idl.py [--modules N] [--repeat R] [--sizes L,L,...] [--check]

The front end: generates an IDL file of about 10,000 lines (218 modules of structs, typedefs,
constants, unions, exceptions and interfaces; see gen_idl.py), runs `miro-idl --ast-json` and
`omniidl -bdump` on it R times, interleaved, and prints the medians and their ratio; then times
both on a tiny file (the manual's Example.idl). Targets: ratio at most 1.0 on the large file
(issue 30), under 0.3 s on tiny files.

Then the back end, at each size of `--sizes` (lines; default 10,000, 50,000 and 100,000, IDL as
gen_idl.py writes it): `miro-idl -o OUT big.idl` (Python: types, codecs, stubs, skeletons,
package `__init__`s) against `omniidl -bcxx big.idl` (C++ headers and stubs), each into a
fresh empty folder, alternating, `--gen-repeat` times; target (issue 30): ratio of the medians
at most 1.0 at every size. And why the front end drives Lark's LALR tables itself
(miro_gen/idl/engine.py): in one process, Lark's own LALR parser, the standalone parser Lark's
generator writes and the engine parse the large file into the same parse tree, each after its
own set-up (compiling the grammar, loading tables); `--no-lark` leaves that out. `--check`
exits 1 when a target is missed.

Both are measured as a user runs them: the installed `miro-idl` script (bytecode compiled and the
grammar tables cached by a warm-up run, as after `pip install`) and Debian's `omniidl`.
`--miro-idl CMD` measures another `miro-idl` (another checkout: `--miro-idl "env
PYTHONPATH=/src/old python -P -m miro_gen.cli.idl"`); `--baseline CMD` times one more with the
front-end rows, interleaved (before and after a change, in the same run); `--workdir DIR` puts
the files in DIR instead of the system's temporary folder. Wall-clock medians are the figures;
the CPU time (user + system) is printed beside them, the steadier figure on a shared machine.
"""

from __future__ import annotations

import argparse
import gc
import os
import resource
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

RATIO_TARGET = 1.0
TINY_TARGET_S = 0.3
GENERATION_TARGET = 1.0
LINES_PER_MODULE = 10027 / 218  # gen_idl.py's modules


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


def run_once(cmd: list[str], env: dict[str, str], cwd: Path | None = None) -> tuple[float, float]:
    """Wall-clock and CPU seconds (user + system, of the command and the processes it waited
    for, such as omniidl's preprocessor) of one run. On a shared machine the CPU time is the
    steadier figure: other work stretches the wall clock, not the CPU a run needs."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=cwd)
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr.decode(errors='replace')}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return elapsed, cpu


def time_once(cmd: list[str], env: dict[str, str]) -> float:
    return run_once(cmd, env)[0]


CPU = " (CPU)"  # suffix of the CPU-time series in measure()'s result


def measure(cmds: dict[str, list[str]], repeat: int, env: dict[str, str]) -> dict[str, list[float]]:
    """Wall-clock times by command name, and CPU times under the name + CPU."""
    times: dict[str, list[float]] = {n: [] for name in cmds for n in (name, name + CPU)}
    for _ in range(repeat):
        for name, cmd in cmds.items():  # interleaved, so drift affects both alike
            wall, cpu = run_once(cmd, env)
            times[name].append(wall)
            times[name + CPU].append(cpu)
    return times


OURS = "miro-idl --ast-json"
THEIRS = "omniidl -bdump"
BEFORE = "--baseline --ast-json"


def compare(
    title: str,
    idl: Path,
    ours: list[str],
    omniidl: str | None,
    repeat: int,
    env: dict[str, str],
    baseline: list[str] | None = None,
) -> dict[str, list[float]]:
    """Time both compilers (and `baseline`, another miro-idl, when given) on `idl`, interleaved,
    and print a table; returns the times by command."""
    cmds = {OURS: [*ours, "--ast-json", str(idl)]}
    if omniidl:
        cmds[THEIRS] = [omniidl, "-bdump", str(idl)]
    if baseline:
        cmds[BEFORE] = [*baseline, "--ast-json", str(idl)]
    times = measure(cmds, repeat, env)
    print()
    print(f"{title:24} {'median s':>9} {'min s':>8} {'max s':>8} {'CPU s':>8} {'CPU min-max':>12}")
    for name in cmds:
        wall, cpu = statistics.median(times[name]), statistics.median(times[name + CPU])
        cpus = times[name + CPU]
        print(
            f"{name:24} {wall:9.3f} {min(times[name]):8.3f} {max(times[name]):8.3f} {cpu:8.3f} "
            f"{min(cpus):5.3f}-{max(cpus):5.3f}"
        )
    if baseline:
        wall = statistics.median(times[OURS]) / statistics.median(times[BEFORE])
        cpu = statistics.median(times[OURS + CPU]) / statistics.median(times[BEFORE + CPU])
        print(f"ratio miro-idl / --baseline: {wall:.2f} (CPU times: {cpu:.2f})")
    return times


def generation(
    big: Path, ours: list[str], omniidl: str | None, repeat: int, env: dict[str, str], tmp: Path
) -> float | None:
    """Time writing Python against omniidl writing C++ from `big`, each into a new empty
    folder per run, alternating (folders are removed only at the end, so no deletion overlaps a
    run). Returns the ratio of the wall-clock medians (None without omniidl)."""
    run_once([*ours, "-o", str(tmp / "warm-up"), str(big)], env)  # bytecode, template caches
    names = ["miro-idl -o OUT", *(["omniidl -bcxx"] if omniidl else [])]
    times: dict[str, list[float]] = {n: [] for name in names for n in (name, name + CPU)}
    for i in range(repeat):
        wall, cpu = run_once([*ours, "-o", str(tmp / f"python{i}"), str(big)], env)
        times[names[0]].append(wall)
        times[names[0] + CPU].append(cpu)
        if omniidl:
            cxx = tmp / f"cxx{i}"
            cxx.mkdir()
            wall, cpu = run_once([omniidl, "-bcxx", str(big.resolve())], env, cwd=cxx)
            times[names[1]].append(wall)
            times[names[1] + CPU].append(cpu)
    lines = big.read_text().count("\n")
    print()
    print(
        f"{f'generating, {lines} lines':24} {'median s':>9} {'min s':>8} {'max s':>8} {'CPU s':>8}"
    )
    for name in names:
        ts = times[name]
        cpu = statistics.median(times[name + CPU])
        print(f"{name:24} {statistics.median(ts):9.3f} {min(ts):8.3f} {max(ts):8.3f} {cpu:8.3f}")
    if not omniidl:
        return None
    ratio = statistics.median(times[names[0]]) / statistics.median(times[names[1]])
    cpu = statistics.median(times[names[0] + CPU]) / statistics.median(times[names[1] + CPU])
    verdict = "ok" if ratio <= GENERATION_TARGET else "MISSED"
    print(
        f"ratio miro-idl -o / omniidl -bcxx at {lines} lines: {ratio:.2f} "
        f"(target <= {GENERATION_TARGET}: {verdict}); CPU times: {cpu:.2f}"
    )
    return ratio


def lark_comparison(big: Path, repeat: int, tmp: Path) -> None:
    """Lark's own LALR parser, and the standalone parser Lark's generator writes, against the
    engine: same grammar, same text, same parse tree; and what each costs before parsing."""
    import importlib.util

    from lark import Lark, Tree

    from miro_gen.idl import engine
    from miro_gen.idl.parser import GRAMMAR_PATH

    class TreeBuilder:  # builds Lark's tree through the engine's rule callbacks
        def __getattr__(self, rule: str) -> object:
            return lambda children: Tree(rule, list(children))

    text = big.read_text()
    setup: dict[str, float] = {}
    start = time.perf_counter()
    lark = Lark(
        GRAMMAR_PATH.read_text(), parser="lalr", lexer="contextual", maybe_placeholders=True
    )
    setup["Lark LALR"] = time.perf_counter() - start

    standalone_py = tmp / "idl_standalone.py"
    generator = [sys.executable, "-m", "lark.tools.standalone", "--maybe_placeholders"]
    generator += ["-l", "contextual", "-o", str(standalone_py), str(GRAMMAR_PATH)]
    subprocess.run(generator, check=True)
    spec = importlib.util.spec_from_file_location("idl_standalone", standalone_py)
    assert spec is not None and spec.loader is not None
    standalone_module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(standalone_module)
    start = time.perf_counter()
    standalone = standalone_module.Lark_StandAlone()
    setup["Lark standalone"] = time.perf_counter() - start

    cache = tmp / "tables"
    cache.mkdir()
    engine.load_tables(str(GRAMMAR_PATH), str(cache))  # as after the first run
    start = time.perf_counter()
    ours = engine.Engine(engine.load_tables(str(GRAMMAR_PATH), str(cache)), TreeBuilder(), str, {})
    setup["engine"] = time.perf_counter() - start

    parsers = {"Lark LALR": lark.parse, "Lark standalone": standalone.parse}
    parsers["engine"] = lambda text: ours.parse(text, [])
    times: dict[str, list[float]] = {name: [] for name in parsers}
    trees = {}
    gc.disable()  # as miro-idl runs
    for _ in range(repeat):
        for name, parse in parsers.items():
            start = time.perf_counter()
            trees[name] = parse(text)
            times[name].append(time.perf_counter() - start)
    gc.enable()
    print()
    print(f"{'parsing (in process)':24} {'setup s':>9} {'median s':>9} {'min s':>8}")
    for name, ts in times.items():
        print(f"{name:24} {setup[name]:9.3f} {statistics.median(ts):9.3f} {min(ts):8.3f}")
    same = trees["Lark LALR"] == trees["engine"] == trees["Lark standalone"]
    ours_s = statistics.median(times["engine"])
    lalr, alone = (statistics.median(times[n]) / ours_s for n in ("Lark LALR", "Lark standalone"))
    print(
        f"engine speed-up: {lalr:.2f}x over Lark's LALR parser, {alone:.2f}x over the standalone "
        f"parser (same tree: {same})"
    )
    print(
        "setup: Lark compiles the grammar, the standalone parser deserialises its tables, "
        "the engine loads its cached tables"
    )


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--modules", type=int, default=218, help="modules in the large file (218)")
    ap.add_argument("--repeat", type=int, default=9, help="runs of each front-end command (9)")
    ap.add_argument(
        "--sizes",
        default="10000,50000,100000",
        help="lines of the files code is generated from, comma-separated ('' for none)",
    )
    ap.add_argument("--gen-repeat", type=int, default=3, help="runs of each generator (3)")
    ap.add_argument("--miro-idl", help="the miro-idl command to measure (default: installed)")
    ap.add_argument(
        "--baseline",
        help="another miro-idl command timed with the front-end rows, interleaved with them "
        '(the code before a change: "env PYTHONPATH=/src/old python -P -m miro_gen.cli.idl")',
    )
    ap.add_argument("--no-lark", action="store_true", help="leave out the parser comparison")
    ap.add_argument(
        "--workdir",
        help="folder for the IDL and the output folders (default: the system's temporary "
        "folder; where a project's generated/ is, a file system's cost of making files can "
        "differ: see bench/README.md)",
    )
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    args = ap.parse_args()

    env = run_env()
    ours = args.miro_idl.split() if args.miro_idl else miro_idl_command()
    omniidl = shutil.which("omniidl")
    tiny = ROOT / "idl" / "Example.idl"
    ok = True
    print(f"load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"work folder: {args.workdir or tempfile.gettempdir()}")
    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        big = Path(tmp) / "big.idl"
        big.write_text("".join(module(i) for i in range(args.modules)))
        lines = big.read_text().count("\n")
        print(f"large file: {lines} lines, {args.modules} modules; {args.repeat} runs each")
        print(f"miro-idl:   {' '.join(ours)}")
        print(f"omniidl:    {omniidl or 'not installed (apt-get install omniidl)'}")

        if args.repeat:
            time_once([*ours, "--ast-json", str(big)], env)  # warm-up: bytecode, grammar cache
            baseline = args.baseline.split() if args.baseline else None
            if baseline:
                time_once([*baseline, "--ast-json", str(big)], env)
            times = compare("large file", big, ours, omniidl, args.repeat, env, baseline)
            if omniidl:
                ratio = statistics.median(times[OURS]) / statistics.median(times[THEIRS])
                verdict = "ok" if ratio <= RATIO_TARGET else "MISSED"
                print(
                    f"ratio miro-idl / omniidl: {ratio:.2f} (target <= {RATIO_TARGET}: {verdict})"
                )
                cpu = statistics.median(times[OURS + CPU]) / statistics.median(times[THEIRS + CPU])
                print(f"ratio of CPU times: {cpu:.2f} (the steadier figure on a shared machine)")
                ok &= ratio <= RATIO_TARGET

            tiny_times = compare(
                "tiny file (Example.idl)", tiny, ours, omniidl, args.repeat, env, baseline
            )
            tiny_median = statistics.median(tiny_times[OURS])
            verdict = "ok" if tiny_median < TINY_TARGET_S else "MISSED"
            print(
                f"miro-idl on a tiny file: {tiny_median:.3f} s "
                f"(target < {TINY_TARGET_S} s: {verdict})"
            )
            ok &= tiny_median < TINY_TARGET_S

        for size in [int(s) for s in args.sizes.split(",") if s]:
            folder = Path(tmp) / f"gen{size}"
            folder.mkdir()
            source = folder / f"big{size}.idl"
            modules = max(1, round(size / LINES_PER_MODULE))
            source.write_text("".join(module(i) for i in range(modules)))
            ratio_gen = generation(source, ours, omniidl, args.gen_repeat, env, folder)
            ok &= ratio_gen is None or ratio_gen <= GENERATION_TARGET
            shutil.rmtree(folder, ignore_errors=True)
        if not args.no_lark:
            lark_comparison(big, args.repeat, Path(tmp))
    print(f"load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0 if ok or not args.check else 1


if __name__ == "__main__":
    sys.exit(main())
