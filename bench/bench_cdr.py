"""Benchmark: generated CDR codecs against PyPI cyclonedds, and large sequences against a plain
copy of their bytes, same types, same values, same run.

    python bench/bench_cdr.py [--check] [--quick]

1. Encode, decode, and both, with miro-idl's generated code and with cyclonedds'
   IdlStruct.serialize()/deserialize(), of Miro::ExampleGroupIDL with 2 and 1,000 points, and of
   laser scans: Miro::RangeScanEventIDL (one group of `long` readings) and a LaserScan struct with
   `sequence<float>` ranges, each with 361 and 1,081 beams. Each side starts from what its own
   decoder gives (array.array for us, lists for cyclonedds); both must produce the same bytes.
   Targets (issues "miro-idl code generation" and "sensor-rate data"): at least 3x faster than
   cyclonedds in every row (the scans' encode+decode: aim 6x).
2. A 10 MiB `sequence<uint8>` and a `sequence<float>` of the same size: encode (from an
   array.array) and decode, against a plain copy of the same number of bytes (`bytes(bytearray)`,
   the memory-bandwidth limit). Target: within 2x of the copy.

Times are medians of 5 repeats (7 with --check); the machine's other load shows in every figure,
so compare the rows of one run. `--check` exits 1 when a target is missed; `--quick` skips 2.
"""

# No "from __future__ import annotations": cyclonedds evaluates its classes' annotations.

import argparse
import importlib
import statistics
import subprocess
import sys
import tempfile
import timeit
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402 - generated package, from generated/ in a checkout

TARGET = 3.0
COPY_TARGET = 2.0
BIG = 10 << 20  # bytes of the large sequences

# A laser scan with float ranges, as ROS's sensor_msgs/LaserScan has it, and the large sequences.
BENCH_IDL = """
#include "Time.idl"
module Bench {
  struct LaserScanIDL {
    Miro::TimeIDL time;
    float angle_min;
    float angle_increment;
    float range_min;
    float range_max;
    sequence<float> ranges;
  };
  struct Bytes { sequence<uint8> data; };
  struct Floats { sequence<float> data; };
};
"""

try:  # the reference implementation; its classes resolve annotations in this module
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl.types import float32, float64, int32, sequence, uint8
except ImportError:  # pragma: no cover
    IdlStruct = None


if IdlStruct is not None:

    @dataclass
    class ExampleStructIDL(IdlStruct, typename="Miro::ExampleStructIDL"):
        a: float64
        b: float64

    @dataclass
    class ExampleGroupIDL(IdlStruct, typename="Miro::ExampleGroupIDL"):
        c: int32
        PointList: sequence[ExampleStructIDL]

    @dataclass
    class TimeIDL(IdlStruct, typename="Miro::TimeIDL"):
        sec: int32
        usec: int32

    @dataclass
    class RangeScanEventIDL(IdlStruct, typename="Miro::RangeScanEventIDL"):
        time: TimeIDL
        range: sequence[sequence[int32]]

    @dataclass
    class LaserScanIDL(IdlStruct, typename="Bench::LaserScanIDL"):
        time: TimeIDL
        angle_min: float32
        angle_increment: float32
        range_min: float32
        range_max: float32
        ranges: sequence[float32]

    @dataclass
    class Bytes(IdlStruct, typename="Bench::Bytes"):
        data: sequence[uint8]


def bench_types() -> Any:
    """The generated package of BENCH_IDL (compiled into a temporary folder)."""
    out = Path(tempfile.mkdtemp(prefix="bench_cdr_"))
    (out / "Bench.idl").write_text(BENCH_IDL)
    cmd = [sys.executable, "-m", "miro_gen.cli.idl", "-I", str(ROOT / "idl"), "-o", str(out)]
    subprocess.run([*cmd, str(out / "Bench.idl")], check=True, capture_output=True, cwd=ROOT)
    sys.path.insert(0, str(out))
    return importlib.import_module("Bench")


def cases(bench: Any) -> list[tuple[str, Any, Any]]:
    """(name, our value, cyclonedds' value): each as its own decoder gives it."""

    def group(n: int) -> tuple[Any, Any]:
        pts = [(i * 0.5, -i * 0.25) for i in range(n)]
        ours = Miro.ExampleGroupIDL(c=n, PointList=[Miro.ExampleStructIDL(a, b) for a, b in pts])
        theirs = ExampleGroupIDL(c=n, PointList=[ExampleStructIDL(a, b) for a, b in pts])
        return ours, theirs

    def long_scan(n: int) -> tuple[Any, Any]:
        readings = [(i * 37) % 8000 for i in range(n)]
        ours = Miro.RangeScanEventIDL(Miro.TimeIDL(1700000000, 250000), [array("i", readings)])
        theirs = RangeScanEventIDL(TimeIDL(1700000000, 250000), [readings])
        return ours, theirs

    def float_scan(n: int) -> tuple[Any, Any]:
        ranges = [((i * 37) % 8000) / 1000 for i in range(n)]
        ranges = array("f", ranges).tolist()  # exactly representable as float32
        head = (-2.35619, 0.0043633, 0.02, 30.0)
        ours = bench.LaserScanIDL(Miro.TimeIDL(1700000000, 250000), *head, array("f", ranges))
        theirs = LaserScanIDL(TimeIDL(1700000000, 250000), *head, ranges)
        return ours, theirs

    return [
        ("ExampleGroupIDL, 2 points", *group(2)),
        ("ExampleGroupIDL, 1,000 points", *group(1000)),
        ("laser scan, 361 long ranges", *long_scan(361)),
        ("laser scan, 1,081 long ranges", *long_scan(1081)),
        ("laser scan, 361 float ranges", *float_scan(361)),
        ("laser scan, 1,081 float ranges", *float_scan(1081)),
    ]


def per_call(fn: Callable[[], Any], repeat: int) -> float:
    """Seconds per call: median of `repeat` runs, each long enough to be timed reliably."""
    number, _ = timeit.Timer(fn).autorange()
    return statistics.median(t / number for t in timeit.repeat(fn, number=number, repeat=repeat))


def operations(ours: Any, theirs: Any) -> list[tuple[str, Callable[[], Any], Callable[[], Any]]]:
    """(operation, ours, cyclonedds') for one value of each."""
    data = ours.serialize()
    if data != theirs.serialize():
        raise SystemExit(f"{ours._type_name}: encodings differ: the comparison is meaningless")
    ours_cls, theirs_cls = type(ours), type(theirs)
    return [
        ("encode", ours.serialize, theirs.serialize),
        ("decode", lambda: ours_cls.deserialize(data), lambda: theirs_cls.deserialize(data)),
        (
            "encode+decode",
            lambda: ours_cls.deserialize(ours.serialize()),
            lambda: theirs_cls.deserialize(theirs.serialize()),
        ),
    ]


def against_cyclonedds(bench: Any, repeat: int) -> bool:
    ok = True
    print(f"{'case':32} {'op':14} {'miro-gen us':>12} {'cyclonedds us':>14} {'ratio':>7}")
    for name, ours, theirs in cases(bench):
        for op, f_ours, f_theirs in operations(ours, theirs):
            t_ours, t_theirs = per_call(f_ours, repeat), per_call(f_theirs, repeat)
            ratio = t_theirs / t_ours
            ok &= ratio >= TARGET
            verdict = "" if ratio >= TARGET else "  MISSED"
            us = f"{t_ours * 1e6:12.1f} {t_theirs * 1e6:14.1f}"
            print(f"{name:32} {op:14} {us} {ratio:6.1f}x{verdict}")
    verdict = "ok" if ok else "MISSED"
    print(f"target: at least {TARGET}x faster than cyclonedds in every row: {verdict}\n")
    return ok


def against_a_copy(bench: Any, repeat: int) -> bool:
    """10 MiB sequences: encode and decode against copying the same number of bytes."""
    ok = True
    source = bytearray(range(256)) * (BIG // 256)
    copy = per_call(lambda: bytes(source), repeat)
    print(f"a plain copy of {BIG >> 20} MiB (bytes(bytearray)): {copy * 1e3:.2f} ms")
    print(f"{'case':32} {'op':14} {'miro-gen ms':>12} {'x the copy':>11}")
    values = [
        ("sequence<uint8>, 10 MiB", bench.Bytes(array("B", source))),
        ("sequence<float>, 10 MiB", bench.Floats(array("f", bytes(source)))),
    ]
    for name, value in values:
        encode, decode, _ = operations(value, value)
        for op, fn, _ in (encode, decode):
            t = per_call(fn, repeat)
            ratio = t / copy
            ok &= ratio <= COPY_TARGET
            verdict = "" if ratio <= COPY_TARGET else "  MISSED"
            print(f"{name:32} {op:14} {t * 1e3:12.2f} {ratio:10.2f}x{verdict}")
    value = bench.Bytes(array("B", source[: 1 << 20]))
    theirs = Bytes(list(source[: 1 << 20]))
    t_ours = per_call(lambda: type(value).deserialize(value.serialize()), repeat)
    t_theirs = per_call(lambda: Bytes.deserialize(theirs.serialize()), repeat)
    print(
        f"(1 MiB sequence<uint8> encode+decode: {t_ours * 1e3:.2f} ms, cyclonedds "
        f"{t_theirs * 1e3:.1f} ms, {t_theirs / t_ours:.0f}x)"
    )
    verdict = "ok" if ok else "MISSED"
    print(f"target: within {COPY_TARGET}x of the copy in every row: {verdict}")
    return ok


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    ap.add_argument("--quick", action="store_true", help="skip the 10 MiB sequences")
    args = ap.parse_args()
    if IdlStruct is None:
        print("cyclonedds is not installed (pip install cyclonedds): nothing to compare with")
        return 1
    bench = bench_types()
    repeat = 7 if args.check else 5
    ok = against_cyclonedds(bench, repeat)
    if not args.quick:
        ok &= against_a_copy(bench, repeat)
    return 0 if ok or not args.check else 1


if __name__ == "__main__":
    sys.exit(main())
