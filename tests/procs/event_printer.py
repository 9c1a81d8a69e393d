"""A consumer for the log tests: prints every event it receives as a JSON line.

    python tests/procs/event_printer.py [common options] CHANNEL [DOMAIN/TYPE ...]

Prints `READY` once subscribed, then one line per event: domain, type, seq, stamp (ns), the
receive time (ns) and the payload's repr.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402, F401 - the event types
import MiroNaming  # noqa: E402

from miro_gen import Server, StructuredEvent, StructuredPushConsumer  # noqa: E402
from miro_gen.transport.events import KEEP_ALL  # noqa: E402


class Printer(StructuredPushConsumer):
    def push_structured_event(self, event: StructuredEvent) -> None:
        line = {
            "domain": event.domain_name,
            "type": event.type_name,
            "seq": event.seq,
            "stamp": round(event.stamp * 1e9),
            "received": time.time_ns(),
            "payload": repr(event.payload),
        }
        print(json.dumps(line), flush=True)


def main() -> None:
    server = Server(sys.argv)
    name, *topics = server.argv[1:]
    while True:  # the player may host the channel: wait for it
        try:
            channel = server.resolve_channel(name)
            break
        except MiroNaming.NotFound:
            time.sleep(0.05)
    consumer = Printer(channel, depth=KEEP_ALL)  # every event, however fast they come
    subs = [tuple(t.rsplit("/", 1)) for t in topics] or [("*", "*")]
    consumer.set_subscriptions(subs)  # type: ignore[arg-type]
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
