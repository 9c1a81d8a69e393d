"""ExampleC, the manual's supplier (§5.2): creates "ExampleEventChannel" and publishes an
ExampleEvent every N seconds, from a reactor timer (the timed publication pattern).

    python services/exampleC.py [common options] [N]        (N: seconds, default 1)
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro
from miro_gen import EventChannelFactory, Server, StructuredPushSupplier
from miro_gen.service.options import service_parser

CHANNEL = "ExampleEventChannel"
EVENT = "ExampleEvent"


class Publisher:
    """The timer handler: builds the next event and pushes it."""

    def __init__(self, supplier: StructuredPushSupplier) -> None:
        self.supplier = supplier
        self.counter = 0

    def handle_timeout(self, _: Any) -> None:
        n = self.counter
        event = Miro.ExampleEventIDL(n, Miro.ExampleStructIDL(float(n), 10.0 + n))
        sent = self.supplier.push(EVENT, event)
        print(f"ExampleEvent #{n} {'published' if sent else 'skipped: no subscribers'}")
        sys.stdout.flush()
        self.counter += 1


def main(argv: list[str] | None = None) -> int:
    server = Server(sys.argv if argv is None else argv)  # takes the common options out
    p = service_parser("exampleC", __doc__.split("\n\n")[0])
    p.add_argument("period", nargs="?", type=float, default=1.0, help="seconds between events")
    args = p.parse_args(server.argv[1:])
    if args.period <= 0:
        p.error("the period must be more than 0 seconds")
    channel = EventChannelFactory(server).create_channel(CHANNEL)
    supplier = StructuredPushSupplier(channel)
    server.reactor().schedule_timer(args.period, args.period, Publisher(supplier))
    print(f"ExampleC publishes {EVENT} on {channel.name} every {args.period:g} s", flush=True)
    server.run()
    return 0


if __name__ == "__main__":
    run_main(main, "exampleC")
