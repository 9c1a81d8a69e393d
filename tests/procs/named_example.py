"""ExampleA's servant behind the public API, for the integration tests.

    python tests/procs/named_example.py [common options] [NAME ...]

Binds each NAME (default ExampleA) with Server.add_to_name_service, prints `READY`, and serves
until SIGINT/SIGTERM, then unbinds. setData(a, b) with a < 0 prints `BUSY` and sleeps -a seconds
first (a test hook: a test that kills the server mid-call waits for that line).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import Miro__POA  # noqa: E402

from miro_gen import Server  # noqa: E402


class Example(Miro__POA.Example):
    def __init__(self) -> None:
        self.data = Miro.ExampleStructIDL()

    def setData(self, a: float, b: float) -> None:
        if a < 0:
            os.write(1, b"BUSY\n")  # the call has reached the servant (one write)
            time.sleep(-a)
        self.data = Miro.ExampleStructIDL(a, b)

    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(self.data.a + 1, self.data.b + 1)


def main() -> None:
    server = Server(sys.argv, lease=float(os.environ.get("MIRO_TEST_LEASE", "3")))
    for name in sys.argv[1:] or ["ExampleA"]:
        server.add_to_name_service(Example(), name)
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
