"""A supplier of ExampleEvents for the log tests.

    python tests/procs/event_supplier.py [common options] CHANNEL COUNT [GAP_MS ...]

Resolves CHANNEL, waits until someone subscribes to ExampleEvent, then pushes COUNT events
`ExampleEventIDL(n, ExampleStructIDL(n, -n))` with the gaps between them cycling through
GAP_MS (default 10), each stamped 1 ms before it is pushed; prints `DONE` and exits.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402

from miro_gen import Server, StructuredPushSupplier  # noqa: E402


def main() -> None:
    server = Server(sys.argv)
    name, count, *gaps = server.argv[1:]
    supplier = StructuredPushSupplier(server.resolve_channel(name))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not supplier.has_subscribers("ExampleEvent"):
        time.sleep(0.01)
    time.sleep(0.2)
    spacing = [float(g) / 1000 for g in gaps] or [0.01]
    due = time.monotonic()
    for n in range(int(count)):
        due += spacing[n % len(spacing)]
        time.sleep(max(0.0, due - time.monotonic()))
        event = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), -float(n)))
        supplier.push("ExampleEvent", event, stamp=time.time() - 0.001)
    time.sleep(0.3)
    print("DONE", flush=True)
    server.shutdown()
    thread.join(5)


if __name__ == "__main__":
    main()
