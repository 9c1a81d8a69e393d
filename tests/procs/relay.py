"""A Miro::Example server whose getData() calls another one: for the A -> B -> A test.

    python tests/procs/relay.py [common options] NAME PEER

getData() on NAME calls PEER's setData(7, 8) and returns (7, 8) when PEER is a plain name, or
returns PEER's getData() when it starts with `@`; so A.getData -> B.getData -> A.setData is a
call back into A while A is still serving the first call. Prints READY once bound.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import Miro__POA  # noqa: E402

from miro_gen import Server  # noqa: E402


class Relay(Miro__POA.Example):
    def __init__(self, server: Server, peer: str) -> None:
        self.server = server
        self.peer = peer
        self.data = Miro.ExampleStructIDL()

    def setData(self, a: float, b: float) -> None:
        self.data = Miro.ExampleStructIDL(a, b)

    def getData(self) -> Miro.ExampleStructIDL:
        if self.peer.startswith("@"):
            other = self.server.resolve_name(self.peer[1:], Miro.Example)
            return other.getData()
        other = self.server.resolve_name(self.peer, Miro.Example)
        other.setData(7.0, 8.0)  # returns only once PEER has served it
        return Miro.ExampleStructIDL(7.0, 8.0)


def main() -> None:
    server = Server(sys.argv)
    name, peer = sys.argv[1], sys.argv[2]
    server.add_to_name_service(Relay(server, peer), name)
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
