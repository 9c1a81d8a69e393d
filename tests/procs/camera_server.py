"""A process serving Miro::Camera over the ZeroMQ transport, for large replies in tests and
bench/bench_rpc.py --sizes.

    python tests/procs/camera_server.py SIZE

Prints `READY <endpoint>` once it serves under the key `Camera`, then serves until killed.
getImage() returns frame 3 with SIZE bytes of data, the byte at i being i % 251 (a pattern a
torn or shifted copy would not keep); getWaitImage() waits 20 ms, as for a camera's next frame,
and returns the same with the next frame number: a servant that blocks, whose reply another
thread sends (transport.rpc.dispatch).
"""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import Miro__POA  # noqa: E402

from miro_gen.transport.reactor import Reactor  # noqa: E402
from miro_gen.transport.rpc.adapter import ObjectAdapter  # noqa: E402
from miro_gen.transport.rpc.invoker import ZmqInvoker  # noqa: E402


def pattern(size: int) -> bytes:
    """The image data of `size` bytes the server returns."""
    return (bytes(range(251)) * (size // 251 + 1))[:size]


class Camera(Miro__POA.Camera):
    def __init__(self, size: int) -> None:
        form = Miro.ImageFormatIDL(size, 1, Miro.ImageEncodingIDL.IMAGE_MONO8, size)
        self.image = Miro.ImageEventIDL(Miro.TimeIDL(1, 2), 3, form, pattern(size))

    def getFormat(self) -> Miro.ImageFormatIDL:
        return self.image.format

    def getImage(self) -> Miro.ImageEventIDL:
        return self.image

    def getWaitImage(self) -> Miro.ImageEventIDL:
        time.sleep(0.02)
        self.image.frame += 1
        return self.image


def main() -> None:
    reactor = Reactor()
    adapter = ObjectAdapter(reactor, ZmqInvoker(reactor.context))
    adapter.activate(Camera(int(sys.argv[1])), b"Camera")
    signal.signal(signal.SIGTERM, lambda *_: reactor.stop())
    reactor.call_soon(lambda: print("READY", adapter.endpoint, flush=True))
    reactor.run()


if __name__ == "__main__":
    main()
