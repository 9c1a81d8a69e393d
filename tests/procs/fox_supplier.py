"""Supplies FoxTest::Scan events (tests/foxglove/FoxTest.idl) for tests/eventlog/test_foxglove.py.

    python tests/procs/fox_supplier.py [common options] CHANNEL

FoxTest must be importable (compiled by the test). Waits for a subscriber, pushes every value
of `scans()`, prints each as a JSON line in the shape Foxglove's MessageReader gives (enums as
numbers, a union as {branch: value}, octets as a list), then `DONE`.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import sys
import threading
import time
from array import array
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import FoxTest  # noqa: E402

from miro_gen import Server, StructuredPushSupplier  # noqa: E402
from miro_gen.runtime.cdr import IdlUnion  # noqa: E402


def scans() -> list[Any]:
    P, M, R = FoxTest.Point, FoxTest.Mode, FoxTest.Reading
    base = {"ok": True, "flags": 0xA5, "big": -(2**40), "ratio": 0.5, "short_name": "scan"}
    return [
        FoxTest.Scan(),  # every member at its default
        FoxTest.Scan(
            id=1,
            name="laser front",
            drive_mode=M.DRIVE,
            points=[P(1.5, -2.25), P(0.0, 1e-3)],
            values=[0.1, 2.0, -3.5],
            origin=P(10.0, 20.0),
            last_reading=R(range=4.75),
            tags=["a", "", "ünïcode"],
            counts=[1, -2, 3],
            blob=bytes([0, 1, 254, 255]),
            modes=[M.PARK, M.IDLE],
            **base,
        ),
        FoxTest.Scan(id=2, name="x", last_reading=R(label="near wall"), **base),
        FoxTest.Scan(id=3, last_reading=R(where=P(-1.0, 7.0)), drive_mode=M.PARK),
        FoxTest.Scan(id=4, last_reading=R(7, 42)),  # the default branch
        FoxTest.Scan(id=5, points=[P(float(i), float(-i)) for i in range(100)]),
    ]


def plain(value: Any) -> Any:
    """`value` as Foxglove's MessageReader decodes it, made JSON."""
    if isinstance(value, enum.IntEnum):
        return int(value)
    if isinstance(value, IdlUnion):
        branch = value._branch()
        return {branch: plain(value._v)} if branch else {}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, list | array):
        return [plain(v) for v in value]
    return value


def main() -> None:
    server = Server(sys.argv)
    supplier = StructuredPushSupplier(server.resolve_channel(server.argv[1]))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not supplier.has_subscribers("Scan"):
        time.sleep(0.01)
    time.sleep(0.2)
    for scan in scans():
        supplier.push("Scan", scan)
        print(json.dumps(plain(scan)), flush=True)
        time.sleep(0.005)
    time.sleep(0.3)
    print("DONE", flush=True)
    server.shutdown()
    thread.join(5)


if __name__ == "__main__":
    main()
