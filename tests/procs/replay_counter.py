"""A consumer for the replay tests: counts the events it receives and whether they came in order.

    python tests/procs/replay_counter.py [common options] CHANNEL DEPTH DELAY

DEPTH: 0 keeps all (KEEP_ALL), N keeps the last N; DELAY: seconds it sleeps per event (a
consumer slower than the replay). Prints `READY` once subscribed, `FIRST` at its first event;
on a `STATS` line on stdin prints `STATS received missed dropped in-order(1/0)`.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402, F401 - the event types
import MiroNaming  # noqa: E402

from miro_gen import Server, StructuredEvent, StructuredPushConsumer  # noqa: E402
from miro_gen.transport.events import KEEP_ALL  # noqa: E402


class Counter(StructuredPushConsumer):
    def __init__(self, *args: object, delay: float, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self.delay = delay
        self.last: dict[str, int] = {}
        self.in_order = True
        self.got = 0

    def push_structured_event(self, event: StructuredEvent) -> None:
        self.got += 1
        if self.got == 1:
            print("FIRST", flush=True)
        last = self.last.get(event.domain_name, -1)
        self.in_order &= event.seq > last
        self.last[event.domain_name] = event.seq
        if self.delay:
            time.sleep(self.delay)


def main() -> None:
    server = Server(sys.argv)
    name, depth, delay = server.argv[1:4]
    while True:  # the player hosts the channel: wait for it
        try:
            channel = server.resolve_channel(name)
            break
        except MiroNaming.NotFound:
            time.sleep(0.05)
    c = Counter(channel, depth=int(depth) or KEEP_ALL, delay=float(delay))
    c.set_subscriptions([("*", "*")])
    server.reactor().call_soon(lambda: print("READY", flush=True))
    threading.Thread(target=server.run, daemon=True).start()
    for line in sys.stdin:
        if line.strip() == "STATS":
            print("STATS", c.got, c.missed, c.dropped, int(c.in_order), flush=True)
    server.shutdown()


if __name__ == "__main__":
    main()
