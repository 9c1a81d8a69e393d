"""A small robot for tests/eventlog/test_foxglove_bridge.py: FoxTest::Scan events, an object,
parameters.

    python tests/procs/fox_robot.py [common options] [--period S]

FoxTest must be importable (compiled by the test). Every --period seconds (default 0.02) pushes
the next of fox_supplier.scans() as a `Scan` event and a numbered FoxTest::Pose as a `Pose`
event, on the EventChannel; serves the manual's Miro::Example as `ExampleA`
(services/exampleA.py) and reads Miro::GpsParameters as its `Gps/Gps` parameter set (so that
they are live: `miro param`). Listens to `Echo` events (FoxTest::Pose) and prints each as a
JSON line `{"echo": ...}` (fox_supplier.plain's shape).
Prints `READY`, then serves until SIGINT/SIGTERM.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [
    str(ROOT / "generated"),
    str(ROOT),
    str(ROOT / "services"),
    str(Path(__file__).parent),
]

import FoxTest  # noqa: E402
from exampleA import ExampleImpl  # noqa: E402
from fox_supplier import plain, scans  # noqa: E402
from Miro.GpsParameters import GpsParameters  # noqa: E402

from miro_gen import Server, StructuredEvent, StructuredPushConsumer, StructuredPushSupplier  # noqa: E402
from miro_gen.params import read_parameters  # noqa: E402


def pose(n: int) -> Any:
    return FoxTest.Pose(FoxTest.Point(n, -n), 0.5 * n, "map", [0.1] * 3, FoxTest.Mode.DRIVE, n)


class Echo(StructuredPushConsumer):
    def push_structured_event(self, event: StructuredEvent) -> None:
        print(json.dumps({"echo": plain(event.payload)}), flush=True)


def main() -> None:
    server = Server(sys.argv)
    args = server.argv[1:]
    period = float(args[args.index("--period") + 1]) if "--period" in args else 0.02
    channel = server.resolve_channel("EventChannel")
    supplier = StructuredPushSupplier(channel)
    echo = Echo(channel)
    echo.set_subscriptions([("*", "Echo")])
    server.add_to_name_service(ExampleImpl(), "ExampleA")
    read_parameters(GpsParameters(), "Gps")
    values = scans()
    n = [0]

    def push(_: Any = None) -> None:
        supplier.push("Scan", values[n[0] % len(values)])
        supplier.push("Pose", pose(n[0]))
        n[0] += 1

    server.reactor().schedule_timer(0.0, period, push)
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
