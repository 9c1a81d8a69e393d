"""A periodic publisher for the --clock log test: the timed-publication pattern of ExampleC.

    python tests/procs/clocked_publisher.py [common options, such as --clock log] PERIOD

Pushes an ExampleEvent on "EventChannel" every PERIOD seconds of the reactor's clock, stamped
with `miro_gen.clock.now()`; prints `READY` once its supplier exists.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402

from miro_gen import Server, StructuredPushSupplier, clock  # noqa: E402


def main() -> None:
    server = Server(sys.argv)
    period = float(server.argv[1])
    supplier = StructuredPushSupplier(server.resolve_channel("EventChannel"))
    count = [0]

    def tick(_: object) -> None:
        n = count[0]
        supplier.push("Tick", Miro.ExampleEventIDL(n, Miro.ExampleStructIDL()), stamp=clock.now())
        count[0] += 1

    server.reactor().schedule_timer(period, period, tick)
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
