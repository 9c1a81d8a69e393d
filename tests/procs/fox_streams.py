"""A camera and a fast small topic, for the fairness tests of
tests/eventlog/test_foxglove_bridge.py.

    python tests/procs/fox_streams.py [common options] CAMERA_BYTES CAMERA_HZ FAST_HZ

FoxTest must be importable (compiled by the test). On the EventChannel, pushes `Camera` events
(FoxTest::Scan numbered by `id`, a `blob` of CAMERA_BYTES) at CAMERA_HZ and `Fast` events
(FoxTest::Pose numbered by `stamp`) at FAST_HZ, on reactor timers (which keep their rate).
Prints `READY`, then `CAMERA N` after every 10th camera frame pushed to a subscriber; serves
until SIGINT/SIGTERM.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import FoxTest  # noqa: E402

from miro_gen import Server, StructuredPushSupplier  # noqa: E402


def main() -> None:
    server = Server(sys.argv)
    size, camera_hz, fast_hz = int(server.argv[1]), float(server.argv[2]), float(server.argv[3])
    supplier = StructuredPushSupplier(server.resolve_channel("EventChannel"))
    blob = bytes(size)
    counts = {"camera": 0, "fast": 0, "sent": 0}

    def camera(_: Any = None) -> None:
        if supplier.push("Camera", FoxTest.Scan(id=counts["camera"], blob=blob)):
            counts["sent"] += 1
            if counts["sent"] % 10 == 0:
                print(f"CAMERA {counts['sent']}", flush=True)
        counts["camera"] += 1

    def fast(_: Any = None) -> None:
        supplier.push("Fast", FoxTest.Pose(stamp=counts["fast"]))
        counts["fast"] += 1

    server.reactor().schedule_timer(0.0, 1.0 / camera_hz, camera)
    server.reactor().schedule_timer(0.0, 1.0 / fast_hz, fast)
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
