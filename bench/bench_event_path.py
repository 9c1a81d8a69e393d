"""Benchmark: the Python an event costs on its way through a supplier and a consumer, with no
transport, beside the CDR encoding and decoding that it includes.

    python bench/bench_event_path.py [--events N] [--runs R]

A StructuredPushSupplier pushes N small ExampleEvents (one reactor turn: encode, batch, one
frame) into a link that keeps the frame; a keep-all StructuredPushConsumer then parses it,
queues the events and delivers them to a handler that counts (decode included). Both run on
this thread, the reactor and the links are stand-ins that run calls in order and hand the
frame over, so that what is timed is the per-event Python of transport.events, the same on
both backbones (bench_backbones.py measures it with Zenoh and ZeroMQ under it). The baseline:
the generated code's serialize() and deserialize() of the same event, N times each. Best of R
(200) repeats, microseconds per event, and the load average.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import zmq  # noqa: E402

from miro_gen import StructuredEvent, StructuredPushConsumer, StructuredPushSupplier  # noqa: E402
from miro_gen.transport.events import KEEP_ALL  # noqa: E402


class _Reactor:
    """Runs what is handed to it, in order, when told to."""

    context = zmq.Context.instance()
    stopping = False

    def __init__(self) -> None:
        self.calls: list[tuple[Callable[..., object], tuple[Any, ...]]] = []

    def call_soon(self, fn: Callable[..., object], *args: Any) -> None:
        self.calls.append((fn, args))

    def run(self) -> None:
        while self.calls:
            calls, self.calls = self.calls, []
            for fn, args in calls:
                fn(*args)


class _Link:
    """Both ends of a channel in one: frames sent are kept until received."""

    connected = True
    moves = 0

    def __init__(self) -> None:
        self.frames: list[tuple[bytes, memoryview]] = []

    def send(self, topic: bytes, body: bytes, copy: bool) -> bool:
        self.frames.append((topic, memoryview(body)))
        return True

    def receive(self) -> tuple[bytes, memoryview] | None:
        return self.frames.pop(0) if self.frames else None

    def subscribe(self, prefix: bytes) -> None:
        pass

    def unsubscribe(self, prefix: bytes) -> None:
        pass

    def close(self) -> None:
        pass


class _Channel:
    name = "Bench"
    domain_name = "bench"

    def __init__(self) -> None:
        self.reactor = _Reactor()
        self.link = _Link()

    def publishing(self, on_connection: Any, on_subscriptions: Any, hwm: int, burst: int) -> Any:
        self.reactor.call_soon(on_connection, True)
        self.reactor.call_soon(on_subscriptions, [(True, b"")])
        return self.link

    def subscribing(self, on_readable: Any, hwm: int, *, keep_all: bool = False) -> Any:
        return self.link


class _Counter(StructuredPushConsumer):
    count = 0

    def push_structured_event(self, event: StructuredEvent) -> None:
        self.count += 1


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--events", type=int, default=1000, help="events per repeat")
    ap.add_argument("--runs", type=int, default=200, help="repeats (the best is kept)")
    args = ap.parse_args()
    n = args.events
    channel = _Channel()
    supplier = StructuredPushSupplier(channel)  # type: ignore[arg-type]
    consumer = _Counter(channel, depth=KEEP_ALL)  # type: ignore[arg-type]
    consumer.set_subscriptions([("*", "ExampleEvent")])
    channel.reactor.run()
    event = Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, 2.0))
    data = event.serialize()
    clock = time.perf_counter
    push = pull = enc = dec = float("inf")
    for _ in range(args.runs):
        t0 = clock()
        for _ in range(n):
            supplier.push("ExampleEvent", event)
        channel.reactor.run()
        t1 = clock()
        consumer._readable()
        channel.reactor.run()
        t2 = clock()
        for _ in range(n):
            event.serialize()
        t3 = clock()
        for _ in range(n):
            Miro.ExampleEventIDL.deserialize(data)
        t4 = clock()
        push, pull = min(push, t1 - t0), min(pull, t2 - t1)
        enc, dec = min(enc, t3 - t2), min(dec, t4 - t3)
    assert consumer.count == n * args.runs and consumer.missed == 0
    us = 1e6 / n
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {n} events a repeat, "
          f"best of {args.runs}; us per event")  # fmt: skip
    rows = (("supplier push + flush", push, "serialize()", enc),
            ("consumer parse + deliver", pull, "deserialize()", dec))  # fmt: skip
    for name, ours, what, base in rows:
        print(f"  {name:28} {ours * us:6.2f}   of which {what:14} {base * us:.2f}")
    total, cdr = (push + pull) * us, (enc + dec) * us
    print(f"  {'together':28} {total:6.2f}   CDR {cdr:.2f}, the rest {total - cdr:.2f} "
          f"(ratio to CDR alone {total / cdr:.2f})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
