"""Benchmark: how long miro-idl and miro-params take to refuse the compiler attacks of issue 33.

    python bench/bench_refusals.py [--repeat 5] [--cpp] [--baseline DIR] [--check]

Each case is a file written to a temporary folder (the texts of tests/idl/test_attack_compilers.py):
macro expansion that doubles at each level (the issue's 20 lines of `#define`, and 2 KB using
them), nesting thousands deep (modules, parentheses; makeParams includes, types, constructor
blocks). Ours is the tool of this checkout (miro-idl generating, with -o), run as a process
as a user runs it (start-up included); the reference in the same run is the same tool on a
small valid file, so the ratio says what a refusal costs beyond an ordinary run. All cases and
the references run interleaved, `--repeat` times; printed: the median seconds, their spread
(min-max), peak memory, the ratio, and the first error line.

`--cpp` also runs gcc's preprocessor (`cc1 -E -P`, what `cpp -P` runs) on the macro cases:
what a C preprocessor, which has no budget, does with them (at most 10 s and 4 GiB each).
`--baseline DIR` runs the tools of another source tree (e.g. `git archive <commit-before-issue-33>
| tar -x -C DIR`) once per case, at most `--baseline-timeout` seconds each: the before figures.

Targets (issue 33): each IDL refusal within a second; miro-params, whose start-up alone takes
about a second on a loaded machine, refuses each case in no more than 1.5 times a normal run.
`--check` exits 1 when one is missed.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 1.0
PARAMS_RATIO = 1.5


def doubling(levels: int, base: str = "x") -> str:
    lines = [f"#define A0 {base}"]
    lines += [f"#define A{i} A{i - 1} A{i - 1}" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def modules(n: int) -> str:
    return "".join(f"module m{i} {{\n" for i in range(n)) + "const long c = 1;\n" + "};\n" * n


_HEAD = '<?xml version="1.0" encoding="UTF-8"?>\n<config>\n'


def item(name: str, body: str = "") -> str:
    return (
        f'<config_group name="g">\n<config_item name="{name}" parent="Miro::Config">\n{body}'
        "</config_item>\n</config_group>\n</config>\n"
    )


IDL_CASES = {
    "doubling #defines, 20 lines": doubling(20) + "typedef long A19;\n",
    "doubling #defines, 2 KB": doubling(20)
    + "".join(f"const long c{i} = A19;\n" for i in range(80)),
    "hidden-name sets, 40 levels": "#define A0\n"
    + "".join(f"#define A{i} A{i - 1} B{i}\n#define B{i} A{i - 1}\n" for i in range(1, 41))
    + "const long c = 1 A40;\n",
    "F(F(...)) doubling, 30 deep": "#define F(x) x x\nconst long c = "
    + "F(" * 30
    + "1"
    + ")" * 30
    + ";\n",
    "#if of a doubling macro": doubling(20) + "#if A19\n#endif\n",
    "5,000 nested modules": modules(5000),
    "5,000 nested parentheses": "const long c = " + "(" * 5000 + "1" + ")" * 5000 + ";\n",
}
PREPROCESSOR_CASES = [name for name in IDL_CASES if "#" in name or "doubling" in name]
PARAMS_CASES = {
    "params: 5,000-deep vector type": _HEAD
    + item(
        "P",
        '<config_parameter name="V" type="'
        + "std::vector&lt;" * 5000
        + "int"
        + "&gt;" * 5000
        + '" />\n',
    ),
    "params: 5,000 nested braces": _HEAD
    + item(
        "P",
        '<config_parameter name="X" type="int" />\n<constructor>'
        + "{" * 5000
        + "x = 1;"
        + "}" * 5000
        + "</constructor>\n",
    ),
    "params: 300 files including each other": "INCLUDE_CHAIN",
}
SMALL_IDL = "module M { struct S { long a; double b; }; interface I { S get(); }; };\n"
SMALL_PARAMS = _HEAD + item("P", '<config_parameter name="X" type="int" default="1" />\n')


@dataclass
class Case:
    name: str
    cmd: list[str]
    reference: str | None  # the case whose median is this one's reference
    times: list[float] = field(default_factory=list)
    peak_mb: list[float] = field(default_factory=list)
    status: int = 0
    first_error: str = ""


def run_measured(
    cmd: list[str], cwd: Path, env: dict[str, str], timeout: float, limit_bytes: int | None = None
) -> tuple[float, float, int, str]:
    """Wall seconds, the child's own peak memory in MiB (wait4), its exit status (-1 when it
    ran out of time) and the first line of its stderr; optionally under an address-space
    limit."""

    def limit() -> None:
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))

    start = time.perf_counter()
    proc = subprocess.Popen(
        cmd,
        cwd=cwd,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=limit,
        start_new_session=True,  # on timeout, its whole group is killed
    )
    assert proc.stderr is not None
    timed_out = False
    deadline = start + timeout
    err = b""
    os.set_blocking(proc.stderr.fileno(), False)
    while True:
        chunk = proc.stderr.read(65536)
        if chunk:
            err += chunk[: max(0, 4096 - len(err))]
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid != 0:
            break
        if time.perf_counter() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            timed_out = True
            _, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.005)
    elapsed = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)  # so Popen does not wait again
    proc.stderr.close()
    first = err.decode(errors="replace").strip().splitlines()
    code = -1 if timed_out else proc.returncode
    return elapsed, usage.ru_maxrss / 1024, code, first[0] if first else ""


def write_cases(folder: Path) -> None:
    for i, text in enumerate(IDL_CASES.values()):
        (folder / f"c{i}.idl").write_text(text, encoding="utf-8")
    (folder / "small.idl").write_text(SMALL_IDL, encoding="utf-8")
    for i, text in enumerate(PARAMS_CASES.values()):
        sub = folder / f"p{i}"
        sub.mkdir()
        if text == "INCLUDE_CHAIN":
            for k in range(300):
                inc = f'<config_global name="include" value="I{k + 1}.h" />\n' if k < 299 else ""
                (sub / f"I{k}.xml").write_text(_HEAD + inc + item(f"I{k}"), encoding="utf-8")
        else:
            (sub / "I0.xml").write_text(text, encoding="utf-8")
    (folder / "small").mkdir()
    (folder / "small" / "I0.xml").write_text(SMALL_PARAMS, encoding="utf-8")


def commands(python: list[str]) -> list[Case]:
    idl = [*python, "-m", "miro_gen.cli.idl", "-o"]  # generating, as the issue measured
    params = [*python, "-m", "miro_gen.cli.params", "-o"]
    cases = [Case("reference: miro-idl, small valid file", [*idl, "gen-small", "small.idl"], None)]
    cases += [
        Case(name, [*idl, f"gen{i}", f"c{i}.idl"], cases[0].name)
        for i, name in enumerate(IDL_CASES)
    ]
    ref = Case(
        "reference: miro-params, small valid file", [*params, "out-small", "small/I0.xml"], None
    )
    cases.append(ref)
    cases += [
        Case(name, [*params, f"out{i}", f"p{i}/I0.xml"], ref.name)
        for i, name in enumerate(PARAMS_CASES)
    ]
    return cases


def gcc_preprocessor() -> str | None:
    """gcc's cc1, which `cpp` runs as a child (run directly, so that its own time and memory
    are measured and a timeout ends it)."""
    if shutil.which("gcc") is None:
        return None
    found = subprocess.run(["gcc", "-print-prog-name=cc1"], capture_output=True, text=True)
    path = found.stdout.strip()
    return path if os.path.isabs(path) and os.access(path, os.X_OK) else None


def env_for(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env.pop("MIRO_DEBUG", None)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="interleaved runs of every case (5)")
    ap.add_argument("--cpp", action="store_true", help="also run gcc's cpp -P on the macro cases")
    ap.add_argument("--baseline", type=Path, help="another source tree: its tools, once per case")
    ap.add_argument("--baseline-timeout", type=float, default=60.0, help="seconds (60)")
    ap.add_argument("--check", action="store_true", help="exit 1 when a refusal takes over 1 s")
    args = ap.parse_args()

    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-refusals-") as tmp:
        folder = Path(tmp)
        write_cases(folder)
        env = env_for(ROOT)
        cases = commands([sys.executable])
        for c in cases:  # warm-up: bytecode, grammar tables
            run_measured(c.cmd, folder, env, 120)
        for _ in range(args.repeat):
            for c in cases:
                elapsed, peak, code, first = run_measured(c.cmd, folder, env, 120)
                c.times.append(elapsed)
                c.peak_mb.append(peak)
                c.status, c.first_error = code, first
        load_after = os.getloadavg()

        medians = {c.name: statistics.median(c.times) for c in cases}
        print(
            f"load average before: {load_before[0]:.2f} {load_before[1]:.2f}, "
            f"after: {load_after[0]:.2f} {load_after[1]:.2f}; {args.repeat} runs each"
        )
        print(f"{'case':40} {'median s':>9} {'min-max s':>13} {'peak MB':>8} {'ratio':>6} exit")
        missed = []
        for c in cases:
            med = medians[c.name]
            ratio = f"{med / medians[c.reference]:.2f}" if c.reference else "1"
            spread = f"{min(c.times):.2f}-{max(c.times):.2f}"
            print(
                f"{c.name:40} {med:9.2f} {spread:>13} {max(c.peak_mb):8.0f} {ratio:>6} {c.status}"
            )
            if c.reference is not None:
                print(f"    {c.first_error[:150]}")
                slow = (
                    med / medians[c.reference] > PARAMS_RATIO
                    if c.name.startswith("params")
                    else med > TARGET_S
                )
                if slow or c.status != 1:
                    missed.append(c.name)

        cc1 = gcc_preprocessor() if args.cpp else None
        if cc1 is not None:
            print("\ngcc's preprocessor (cc1 -E -P) on the same macro files (once each; at most")
            print("10 s and 4 GiB):")
            for i, name in enumerate(IDL_CASES):
                if name not in PREPROCESSOR_CASES:
                    continue
                elapsed, peak, code, _ = run_measured(
                    [cc1, "-E", "-quiet", "-P", f"c{i}.idl", "-o", os.devnull],
                    folder,
                    dict(os.environ),
                    10.0,
                    4 << 30,
                )
                what = "timed out" if code == -1 else f"exit {code}"
                print(f"{name:40} {elapsed:9.2f} s {peak:8.0f} MB  {what}")

        if args.baseline is not None:
            print(f"\nbaseline {args.baseline} (once each; at most {args.baseline_timeout:.0f} s):")
            base_env = env_for(args.baseline.resolve())
            for c in commands([sys.executable]):
                elapsed, peak, code, first = run_measured(
                    c.cmd, folder, base_env, args.baseline_timeout
                )
                what = "timed out" if code == -1 else f"exit {code}"
                print(f"{c.name:40} {elapsed:9.2f} s {peak:8.0f} MB  {what}  {first[:90]}")

    target = (
        f"each miro-idl refusal within {TARGET_S:.0f} s, each miro-params one within "
        f"{PARAMS_RATIO}x a normal run, all exit 1"
    )
    print(f"\ntarget ({target}): " + (f"missed: {', '.join(missed)}" if missed else "met"))
    return 1 if args.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())
