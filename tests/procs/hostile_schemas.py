"""A service whose objects describe their interfaces with hostile schemas, for the live tools'
tests of schemas from elsewhere (tests/live/test_foreign_schemas.py).

    python tests/procs/hostile_schemas.py FILE [common options]

Serves two objects that work as ExampleA does, bound as `Include` and `Huge`, but that give,
when asked for their interface schema (MiroService::Service::interface_schema), `#include "FILE"`
before an interface, and a schema of over 10 MB. Prints `READY`, and serves until SIGINT or
SIGTERM.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import Miro__POA  # noqa: E402

from miro_gen import Server  # noqa: E402

HUGE_BYTES = 10 << 20


class Example(Miro__POA.Example):
    def __init__(self) -> None:
        self.data = Miro.ExampleStructIDL()

    def setData(self, a: float, b: float) -> None:
        self.data = Miro.ExampleStructIDL(a, b)

    def getData(self) -> Miro.ExampleStructIDL:
        return self.data


def huge_schema() -> str:
    """An interface schema of over HUGE_BYTES: plain declarations, thousands of them."""
    structs = []
    size, n = 0, 0
    while size < HUGE_BYTES:
        text = f"  struct S{n} {{ long x; double y; string z; sequence<octet> w; }};"
        structs.append(text)
        size += len(text) + 1
        n += 1
    body = "\n".join(structs)
    return f"module Hostile {{\n{body}\n  interface Huge {{ void f(); }};\n}};\n"


def main() -> None:
    secret = sys.argv.pop(1)

    class Include(Example):
        _repo_id = "IDL:Hostile/Include:1.0"
        _interface_schema = (
            f'#include "{secret}"\nmodule Hostile {{ interface Include {{ void f(); }}; }};\n'
        )

    class Huge(Example):
        _repo_id = "IDL:Hostile/Huge:1.0"
        _interface_schema = huge_schema()

    server = Server(sys.argv)
    server.add_to_name_service(Include(), "Include")
    server.add_to_name_service(Huge(), "Huge")
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
