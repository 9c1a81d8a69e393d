"""A server whose one call answers a large reply after a while, for the test that a server
told to stop still delivers the replies of the calls it was serving (tests/service/).

    python tests/procs/large_reply_server.py [common options] SIZE SECONDS

Serves an object under the name `Large`; prints `READY <endpoint> <key hex>` once it serves.
Its operation `large` (no arguments, raw bytes: the transport's view of a call) prints `BUSY`,
sleeps SECONDS, and answers a CDR body of SIZE bytes: `reply(SIZE)`, a header, the size as a
ulong and SIZE - 8 bytes 0x5a. Ends on SIGTERM/SIGINT as any server does (`Server.run`),
letting the calls it serves take up to 60 s to finish (not 2: a loaded machine may take longer
than 2 s over a 1 s call).
"""

from __future__ import annotations

import os
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

from miro_gen.lifecycle import defer_signals, run_main  # noqa: E402

if __name__ == "__main__":
    defer_signals()

from miro_gen import Server  # noqa: E402
from miro_gen.runtime.cdr import HEADER_LE  # noqa: E402
from miro_gen.runtime.rpc import Dispatcher, Invoker, Servant  # noqa: E402


def reply(size: int) -> bytes:
    """The reply body of a `large` call of `size` bytes."""
    return HEADER_LE + struct.pack("<I", size) + b"\x5a" * (size - 8)


class Large(Servant):
    _repo_id = "IDL:Test/Large:1.0"

    def __init__(self, size: int, seconds: float) -> None:
        self.size = size
        self.seconds = seconds

    def _large(self, body: bytes, invoker: Invoker) -> bytes:
        os.write(1, b"BUSY\n")
        time.sleep(self.seconds)
        return reply(self.size)

    _dispatch: dict[str, Dispatcher] = {
        "large": lambda servant, body, invoker: servant._large(body, invoker)
    }


def main() -> int:
    server = Server(sys.argv)
    server.drain_timeout = 60.0
    size, seconds = int(server.argv[1]), float(server.argv[2])
    ref = server.add_to_name_service(Large(size, seconds), "Large")
    server.reactor().call_soon(
        lambda: os.write(1, f"READY {ref.endpoint} {ref.key.hex()}\n".encode())
    )
    server.run()
    return 0


if __name__ == "__main__":
    run_main(main, "large_reply_server")
