"""A supplier of ExampleEvents for the Qt tests: a real process on the public API.

    python tests/procs/flood_supplier.py [common options] CHANNEL COUNT [RATE]

Hosts CHANNEL, prints `READY`, waits for a subscriber to ExampleEvent, then pushes COUNT
events (counter 0 .. COUNT-1) at RATE a second (0 or absent: as fast as it can), then, after
a pause, one more (counter COUNT: a final event that no flood can have crowded out), prints
`SENT COUNT SECONDS` (the flood's duration) and serves on until SIGTERM.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402

from miro_gen import EventChannelFactory, Server, StructuredPushSupplier  # noqa: E402


def flood(supplier: StructuredPushSupplier, count: int, rate: float) -> None:
    while not supplier.has_subscribers("ExampleEvent"):
        time.sleep(0.01)
    time.sleep(0.3)  # the slow joiner: let the subscriber's connection settle
    start = time.monotonic()
    for n in range(count):
        supplier.push("ExampleEvent", Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(n, -n)))
        if rate > 0:
            delay = start + (n + 1) / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    took = time.monotonic() - start
    time.sleep(0.5)
    supplier.push("ExampleEvent", Miro.ExampleEventIDL(count, Miro.ExampleStructIDL(count, 0)))
    print(f"SENT {count} {took:.3f}", flush=True)


def main() -> None:
    server = Server(sys.argv)
    name, count = server.argv[1], int(server.argv[2])
    rate = float(server.argv[3]) if len(server.argv) > 3 else 0.0
    supplier = StructuredPushSupplier(EventChannelFactory(server).create_channel(name))
    threading.Thread(target=flood, args=(supplier, count, rate), daemon=True).start()
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
