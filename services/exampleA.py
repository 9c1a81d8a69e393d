"""ExampleA, the manual's server (§5.1): implements Miro::Example and binds it as "ExampleA".

    python services/exampleA.py [common options such as -MNC robot1 -MLL 9 -MLF MIRO]

setData(a, b) stores the two values; each getData() returns them one higher than before, as
the manual's run shows. Serves until Ctrl-C (or SIGTERM), then unbinds its name.
"""

from __future__ import annotations

import sys
import threading
from functools import partial
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro
import Miro__POA
from miro_gen import Server, log, nonblocking
from miro_gen.service.options import service_parser

_log = log.logger("MIRO")


class ExampleImpl(Miro__POA.Example):
    """The Example interface's implementation: two numbers, stepped on every poll. Both
    operations return at once, so they are marked @nonblocking: the server runs them where the
    request arrives, without a hand-off to its worker pool."""

    def __init__(self) -> None:
        self._lock = threading.Lock()  # calls arrive on several worker threads
        self._data = Miro.ExampleStructIDL()

    @nonblocking
    def setData(self, a: float, b: float) -> None:
        with self._lock:
            self._data = Miro.ExampleStructIDL(a, b)
        _log.debug("setData(%g, %g)", a, b)

    @nonblocking
    def getData(self) -> Miro.ExampleStructIDL:
        with self._lock:
            self._data = Miro.ExampleStructIDL(self._data.a + 1, self._data.b + 1)
            data = self._data
        _log.debug("getData() -> %g, %g", data.a, data.b)
        return data


def main(argv: list[str] | None = None) -> int:
    server = Server(sys.argv if argv is None else argv)  # takes the common options out
    service_parser("exampleA", __doc__.split("\n\n")[0]).parse_args(server.argv[1:])
    server.add_to_name_service(ExampleImpl(), "ExampleA")
    server.reactor().call_soon(partial(print, flush=True), "ExampleA is ready")  # once it runs
    server.run()
    return 0


if __name__ == "__main__":
    run_main(main, "exampleA")
