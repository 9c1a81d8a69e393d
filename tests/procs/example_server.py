"""A process serving Miro::Example over the ZeroMQ transport, for the integration tests.

    python tests/procs/example_server.py [KEY]

Prints `READY <endpoint>` once it serves, then serves until killed. Its servant behaves as
ExampleA does, plus a test hook: setData(a, b) with a < 0 prints `BUSY` and sleeps for -a
seconds first, so that tests can catch it in the middle of a call. The key `Quick` serves the
same with getData marked @nonblocking (run on the reactor thread).
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import Miro__POA  # noqa: E402

from miro_gen import nonblocking  # noqa: E402
from miro_gen.transport.reactor import Reactor  # noqa: E402
from miro_gen.transport.rpc.adapter import ObjectAdapter  # noqa: E402
from miro_gen.transport.rpc.invoker import ZmqInvoker  # noqa: E402


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


class QuickExample(Example):
    """The same, with getData run on the reactor thread (served under the key `Quick`)."""

    @nonblocking
    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(self.data.a + 1, self.data.b + 1)


def main() -> None:
    key = (sys.argv[1] if len(sys.argv) > 1 else "ExampleA").encode()
    reactor = Reactor()
    invoker = ZmqInvoker(reactor.context)
    adapter = ObjectAdapter(reactor, invoker)
    invoker.adapter = adapter
    adapter.activate(Example(), key)
    adapter.activate(QuickExample(), b"Quick")
    signal.signal(signal.SIGTERM, lambda *_: reactor.stop())
    reactor.call_soon(lambda: print("READY", adapter.endpoint, flush=True))
    reactor.run()


if __name__ == "__main__":
    main()
