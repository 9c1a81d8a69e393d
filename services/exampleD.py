"""ExampleD, the manual's consumer (§5.2): subscribes to ExampleEvent on "ExampleEventChannel"
and prints each event it receives.

    python services/exampleD.py [common options] [--domain D]

D is the supplier's naming context (its robot); by default events from any.
"""

from __future__ import annotations

import sys
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro  # noqa: F401 - the package that has the event type, for decoding
import MiroNaming
from miro_gen import Server, StructuredEvent, StructuredPushConsumer
from miro_gen.service.options import service_parser

CHANNEL = "ExampleEventChannel"
EVENT = "ExampleEvent"


class ExampleConsumer(StructuredPushConsumer):
    def push_structured_event(self, event: StructuredEvent) -> None:
        data = event.payload.data
        print(
            f"Received {event.type_name} #{event.payload.counter} from {event.domain_name}: "
            f"a = {data.a:g}, b = {data.b:g}"
        )
        sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    server = Server(sys.argv if argv is None else argv)  # takes the common options out
    p = service_parser("exampleD", __doc__.split("\n\n")[0])
    p.add_argument("--domain", default="*", help="the supplier's naming context (default: any)")
    args = p.parse_args(server.argv[1:])
    try:
        channel = server.resolve_channel(CHANNEL)
    except MiroNaming.NotFound as e:
        print(f"exampleD: {e.name} is not bound: start exampleC first", file=sys.stderr)
        return 1
    consumer = ExampleConsumer(channel)
    consumer.set_subscriptions([(args.domain, EVENT)])
    print(f"ExampleD listens to {EVENT} on {channel.name}", flush=True)
    server.run()
    return 0


if __name__ == "__main__":
    run_main(main, "exampleD")
