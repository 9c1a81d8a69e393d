"""ExampleB, the manual's client (§5.1): finds ExampleA in the naming service and polls it.

    python services/exampleB.py [--count N] [--period S] [--wait S] [common options]

Sets a and b, gets them back (ExampleA steps them), and sets the values it got plus one, N times
(default: until Ctrl-C), printing what the manual prints:

    The object 'ExampleA' has been found in the naming service
    Variables a and b have been set to: 0 and 10
    Retrieved variables a and b are: 1 and 11
    ...
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro
from miro_gen import Client
from miro_gen.service.options import service_parser


def number(x: float) -> str:
    """A double as C++'s ostream prints it (`0`, `10`, `1.5`), as in the manual's output."""
    return f"{x:g}"


def main(argv: list[str] | None = None) -> int:
    client = Client(sys.argv if argv is None else argv)  # takes the common options out
    p = service_parser("exampleB", __doc__.split("\n\n")[0])
    p.add_argument("--count", type=int, default=0, help="rounds to run (default: until Ctrl-C)")
    p.add_argument("--period", type=float, default=1.0, help="seconds between rounds")
    p.add_argument(
        "--wait", type=float, default=0.0, help="seconds to wait for ExampleA (default: none)"
    )
    args = p.parse_args(client.argv[1:])
    example = client.resolve_name("ExampleA", Miro.Example, wait=args.wait)
    print("The object 'ExampleA' has been found in the naming service", flush=True)
    a, b = 0.0, 10.0
    rounds = 0
    try:
        while not args.count or rounds < args.count:
            example.setData(a, b)
            print(f"Variables a and b have been set to: {number(a)} and {number(b)}", flush=True)
            data = example.getData()
            print(f"Retrieved variables a and b are: {number(data.a)} and {number(data.b)}")
            sys.stdout.flush()
            a, b = data.a + 1, data.b + 1
            rounds += 1
            time.sleep(args.period)
    except KeyboardInterrupt:
        pass
    finally:
        client.close()
    return 0


if __name__ == "__main__":
    run_main(main, "exampleB")
