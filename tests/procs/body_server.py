"""A process serving an object that checks the request bodies it receives, for large request
bodies in shared memory (tests/transport/test_shm_requests.py).

    python tests/procs/body_server.py

Prints `READY <endpoint> <pid>` once it serves under the key `Body`, then serves until killed.
Its operations take any body (raw bytes, no CDR: the transport's view of a call) and answer
with a CDR body holding the body's CRC-32 and length (two ulongs): `crc` at once, `slow_crc`
after 300 ms (a call its caller may be killed in the middle of); `size` answers 0 and the
length only (bench/large_requests.py). `stats` answers how many request bodies it read from
callers' shared memory and how many it could not read.
"""

from __future__ import annotations

import signal
import struct
import sys
import time
import zlib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

from miro_gen.runtime.cdr import HEADER_LE  # noqa: E402
from miro_gen.runtime.rpc import Dispatcher, Invoker, Servant  # noqa: E402
from miro_gen.transport.reactor import Reactor  # noqa: E402
from miro_gen.transport.rpc.adapter import ObjectAdapter  # noqa: E402
from miro_gen.transport.rpc.invoker import ZmqInvoker  # noqa: E402

PAIR = struct.Struct("<II")


def answer(body: bytes) -> bytes:
    """What `crc` answers for `body`: CRC-32 and length."""
    return HEADER_LE + PAIR.pack(zlib.crc32(body), len(body))


def _crc(servant: Any, body: bytes, invoker: Invoker) -> bytes:
    return answer(body)


def _slow_crc(servant: Any, body: bytes, invoker: Invoker) -> bytes:
    time.sleep(0.3)
    return answer(body)


def _size(servant: Any, body: bytes, invoker: Invoker) -> bytes:
    return HEADER_LE + PAIR.pack(0, len(body))


def _stats(servant: Any, body: bytes, invoker: Invoker) -> bytes:
    requests = servant.adapter.requests  # None with shared memory off
    counts = (requests.read, requests.refused) if requests is not None else (0, 0)
    return HEADER_LE + PAIR.pack(*counts)


class Body(Servant):
    _repo_id = "IDL:Test/Body:1.0"
    _dispatch: dict[str, Dispatcher] = {
        "crc": _crc,
        "slow_crc": _slow_crc,
        "size": _size,
        "stats": _stats,
    }

    def __init__(self, adapter: ObjectAdapter) -> None:
        self.adapter = adapter


def main() -> None:
    import os

    reactor = Reactor()
    adapter = ObjectAdapter(reactor, ZmqInvoker(reactor.context))
    adapter.activate(Body(adapter), b"Body")
    signal.signal(signal.SIGTERM, lambda *_: reactor.stop())
    reactor.call_soon(lambda: print("READY", adapter.endpoint, os.getpid(), flush=True))
    reactor.run()


if __name__ == "__main__":
    main()
