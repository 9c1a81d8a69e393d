"""A service of types the tools' machine does not have: it publishes `Reading` events on a channel
of its own and serves `Lab::Store`, for the live tools' tests (tests/live/test_live_types.py).

    python tests/procs/lab_service.py GENERATED [common options]

GENERATED holds the Python miro-idl made of the test's Lab.idl. Prints `READY` once its channel
and object are bound; pushes a Reading every 50 ms (offered at once, sent when someone
subscribes) until SIGINT/SIGTERM.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [sys.argv.pop(1), str(ROOT / "generated"), str(ROOT)]

import Lab  # noqa: E402
import Lab__POA  # noqa: E402

from miro_gen import EventChannelFactory, Server, StructuredPushSupplier  # noqa: E402

BLOB = bytes(range(256)) * 4  # 1024 bytes


class Store(Lab__POA.Store):
    def numbers(self, count: int) -> list[int]:
        return list(range(count))

    def latest(self) -> Lab.Reading:
        return Lab.Reading(7, BLOB, [0.5] * 1081)


def main() -> None:
    server = Server(sys.argv)
    channel = EventChannelFactory(server).create_channel("Sensors")
    supplier = StructuredPushSupplier(channel)
    server.add_to_name_service(Store(), "Store")
    n = [0]

    def push(_: Any = None) -> None:
        supplier.push("Reading", Lab.Reading(n[0], BLOB, [0.25] * 1081))
        n[0] += 1

    server.reactor().schedule_timer(0.0, 0.05, push)
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
