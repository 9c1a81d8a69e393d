"""Benchmark: loading run-time parameter documents with 10,000 parameters.

    python bench/bench_params.py [--check]

Compiles a compile-time file with miro-params into a temporary folder, writes run-time
documents, and times `ConfigDocument(["-MCF", FILE])` + `set_section` + `get_parameters` (file
read, safe XML parse, conversion of every value, the result applied) for:

* nested: 1,000 structures of 10 parameters each (ints, doubles, strings, bools, angles,
  enumerations, times) in a vector, as a robot description with many devices;
* flat: one `vector<double>` of 10,000 `<parameter value=.../>` elements (the manual's form);
* compact: the same vector in one `value="..."` attribute.

Target (issue 5, "miro-params"): under 0.5 s each. `--check` exits 1 when a row misses it.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

from miro_gen.params.runtime.document import ConfigDocument  # noqa: E402

TARGET = 0.5  # seconds
N = 10_000

COMPILE_TIME = """\
<config>
  <config_global name="namespace" value="BenchParams" />
  <config_group name="bench">
    <config_item name="Device" parent="Miro::Config" final="false">
      <config_parameter name="Name" type="std::string" />
      <config_parameter name="Id" type="int" />
      <config_parameter name="Rate" type="double" measure="Hz" />
      <config_parameter name="Gain" type="float" />
      <config_parameter name="Enabled" type="bool" />
      <config_parameter name="Heading" type="angle" measure="&deg;" />
      <config_parameter name="Mode" type="Enumeration" values="Idle, Run, Stop" />
      <config_parameter name="Period" type="ACE_Time_Value" />
      <config_parameter name="Port" type="unsigned short" />
      <config_parameter name="Offset" type="long" />
    </config_item>
    <config_item name="Robot" parent="Miro::Config">
      <config_parameter name="Devices" type="std::vector&lt;DeviceParameters&gt;" />
      <config_parameter name="Samples" type="std::vector&lt;double&gt;" />
    </config_item>
  </config_group>
</config>
"""


def nested_document(n_devices: int) -> str:
    devices = "".join(
        "<parameter>"
        f'<parameter name="Name" value="device {i}"/>'
        f'<parameter name="Id" value="{i}"/>'
        f'<parameter name="Rate" value="{i * 0.5}"/>'
        '<parameter name="Gain" value="1.25"/>'
        f'<parameter name="Enabled" value="{"true" if i % 2 else "false"}"/>'
        f'<parameter name="Heading" value="{i % 360}"/>'
        '<parameter name="Mode" value="Run"/>'
        '<parameter name="Period" value="0, 100000"/>'
        f'<parameter name="Port" value="{5000 + i % 1000}"/>'
        f'<parameter name="Offset" value="{-i}"/>'
        "</parameter>\n"
        for i in range(n_devices)
    )
    return (
        '<config>\n<section name="bench">\n<parameter name="Robot">\n'
        f'<parameter name="Devices">\n{devices}</parameter>\n</parameter>\n</section>\n</config>\n'
    )


def flat_document(n: int, compact: bool) -> str:
    if compact:
        samples = f'<parameter name="Samples" value="{" ".join(str(i * 0.25) for i in range(n))}"/>'
    else:
        items = "\n".join(f'<parameter value="{i * 0.25}"/>' for i in range(n))
        samples = f'<parameter name="Samples">\n{items}\n</parameter>'
    return (
        '<config>\n<section name="bench">\n<parameter name="Robot">\n'
        f"{samples}\n</parameter>\n</section>\n</config>\n"
    )


def load(cls: type, path: Path) -> object:
    params = cls()
    doc = ConfigDocument(["-MCF", str(path)])
    doc.set_section("bench")
    doc.get_parameters("Robot", params)
    return params


def best_of(fn: Callable[[], object], repeat: int = 5) -> tuple[float, float]:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times)


def run() -> list[tuple[str, int, float, float]]:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        src = folder / "Bench.xml"
        src.write_text(COMPILE_TIME, encoding="utf-8")
        subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.params", "-o", str(folder / "out"), str(src)],
            check=True,
            cwd=ROOT,
            capture_output=True,
        )
        sys.path.insert(0, str(folder / "out"))
        module = importlib.import_module("BenchParams.Bench")
        robot = module.RobotParameters
        rows = []
        cases = [
            ("nested: 1,000 x 10 parameters", nested_document(N // 10), N),
            ("flat: vector of 10,000 elements", flat_document(N, compact=False), N),
            ("compact: 10,000 numbers in value=", flat_document(N, compact=True), N),
        ]
        for label, text, count in cases:
            path = folder / "doc.xml"
            path.write_text(text, encoding="utf-8")
            params = load(robot, path)  # warm up, and check what was read
            got = len(params.devices) * 10 if params.devices else len(params.samples)
            assert got == count, (label, got)
            best, median = best_of(lambda: load(robot, path))  # noqa: B023 - called at once
            rows.append((label, count, best, median))
        sys.path.remove(str(folder / "out"))
        return rows


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help=f"exit 1 if a row takes {TARGET} s or more")
    args = p.parse_args()
    rows = run()
    print(f"{'document':<38} {'parameters':>10} {'best':>9} {'median':>9}  target < {TARGET} s")
    failed = False
    for label, count, best, median in rows:
        ok = median < TARGET
        failed |= not ok
        print(f"{label:<38} {count:>10,} {best:>8.3f}s {median:>8.3f}s  {'ok' if ok else 'SLOW'}")
    return 1 if args.check and failed else 0


if __name__ == "__main__":
    sys.exit(main())
