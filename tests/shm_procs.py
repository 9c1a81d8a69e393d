"""Supplier and consumer processes of large events, for tests/transport/test_shm_events.py:
real processes on one host, so that large events take shared memory.

    python tests/shm_procs.py supply NAMING CHANNEL COUNT SIZE [PACE]
        waits for a subscriber, pushes COUNT images of SIZE bytes (0: until killed), PACE
        seconds apart; prints `RING yes|no` after the first, `SENT n dropped` at the end, then
        waits for its stdin to close.
    python tests/shm_procs.py consume NAMING CHANNEL DEPTH DELAY [zero-copy]
        keeps DEPTH events (0: all), takes DELAY s over each; prints `READY`, then `E n ok` per
        event (ok: its checksum holds); `STATS` on stdin prints `STATS received missed
        dropped torn segments`.

    python tests/shm_procs.py flood NAMING CHANNEL COUNT [RATE [KEEP_ALL]]
        waits for a subscriber (and for KEEP_ALL keep-all consumers that return credits, then
        pushes the first event, prints `PUSHING` and waits for `GO` on stdin), pushes COUNT
        small events (Miro::TimeIDL), RATE a second (default:
        flat out); prints `SENT sent dropped stalls waited` (stalls: times it stopped waiting
        for a keep-all consumer; waited: pushes that waited for room), then waits for its
        stdin to close; `PUSH` on stdin pushes one more and prints `SENT ...` again.
    python tests/shm_procs.py count NAMING CHANNEL [DEPTH]
        a consumer of them, keep-all by default; `STATS` prints `STATS received missed
        dropped`.

Each image's data is its number repeated, and its time's usec field is the CRC-32 of the data:
a payload read while it was rewritten (torn) fails the check.
"""

from __future__ import annotations

import os
import sys
import threading
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402

from miro_gen import Server, StructuredPushConsumer, StructuredPushSupplier  # noqa: E402
from miro_gen.transport.events import StructuredEvent  # noqa: E402

# One line at a time: a consumer prints an event's line on its reactor thread while its main
# thread answers STATS, and print() writes its words one by one (two threads' lines came out
# mixed, `E 410 STATS 1 2 3 4 5`, which the test's reader cannot parse).
_say = threading.Lock()


def say(*words: object) -> None:
    """Print one line of the protocol, whole, whatever other thread prints."""
    line = " ".join(map(str, words)) + "\n"
    with _say:
        sys.stdout.write(line)
        sys.stdout.flush()


def image(n: int, size: int) -> Miro.ImageEventIDL:
    data = n.to_bytes(4, "little") * (size // 4)
    form = Miro.ImageFormatIDL(1024, size // 3072, Miro.IMAGE_RGB8, 3072)
    return Miro.ImageEventIDL(Miro.TimeIDL(n, zlib.crc32(data) & 0x7FFFFFFF), n, form, data)


def intact(e: Miro.ImageEventIDL) -> bool:
    return zlib.crc32(e.data) & 0x7FFFFFFF == e.time.usec


def supply(naming: str, channel_name: str, count: int, size: int, pace: float) -> None:
    server = Server(["supplier", "--naming", naming, "-MNC", "s"])
    threading.Thread(target=server.run, daemon=True).start()
    channel = server.resolve_channel(channel_name)
    supplier = StructuredPushSupplier(channel)
    while not supplier.has_subscribers("Image"):
        time.sleep(0.01)
    time.sleep(0.3)
    n = 0
    while count == 0 or n < count:
        supplier.push("Image", image(n, size))
        if n == 0:
            ring = supplier._topics["Image"].ring
            say("RING", "yes" if ring is not None else "no")
        n += 1
        if pace:
            time.sleep(pace)
    time.sleep(0.5)
    say("SENT", supplier.sent, supplier.dropped)
    sys.stdin.read()
    server.shutdown()


class Checker(StructuredPushConsumer):
    def __init__(self, *args: object, delay: float, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self.delay = delay

    def push_structured_event(self, event: StructuredEvent) -> None:
        p = event.payload
        if self.delay:
            time.sleep(self.delay)
        if self.zero_copy and type(p.data) is not memoryview:
            say("NOT-A-VIEW")
        say("E", p.time.sec, int(intact(p)))


def consume(naming: str, channel_name: str, depth: int, delay: float, zero_copy: bool) -> None:
    server = Server(["consumer", "--naming", naming, "-MNC", "c"])
    channel = server.resolve_channel(channel_name)
    c = Checker(channel, depth=depth, delay=delay, zero_copy=zero_copy)
    c.set_subscriptions([("s", "Image")])
    threading.Thread(target=server.run, daemon=True).start()
    say("READY")
    for line in sys.stdin:
        if line.strip() == "STATS":
            segments = len(c._segments._by_id)
            say("STATS", c.received, c.missed, c.dropped, c.torn, segments)
    server.shutdown()


# The event types of a flood of several topics, in turn (all Miro::TimeIDL).
TYPES = ("Tick", "Tock", "Tack", "Tuck")


def flood(
    naming: str, channel_name: str, count: int, rate: float, keep_all: int, topics: int = 1
) -> None:
    server = Server(["flooder", "--naming", naming, "-MNC", "s"])
    threading.Thread(target=server.run, daemon=True).start()
    supplier = StructuredPushSupplier(server.resolve_channel(channel_name))
    types = TYPES[:topics]
    for t in types if topics > 1 else ():  # each topic's keep-all consumer known
        while not supplier.has_subscribers(t) or not getattr(
            supplier._topics[t].credits, "readers", None
        ):
            time.sleep(0.01)
    while not supplier.has_subscribers("Tick"):
        time.sleep(0.01)
    if keep_all:
        while len(getattr(supplier._topics["Tick"].credits, "readers", [])) < keep_all:
            time.sleep(0.01)
            supplier.has_subscribers("Tick")
        time.sleep(0.3)
        supplier.push("Tick", Miro.TimeIDL(0, 0))
        say("PUSHING")
        while sys.stdin.readline().strip() != "GO":
            pass
    time.sleep(0.3)
    start = time.monotonic()
    for n in range(1 if keep_all else 0, count):
        supplier.push(types[n % topics], Miro.TimeIDL(n, 0))
        if rate and n % 20 == 19:  # paced: many small frames, not a few large ones
            time.sleep(max(0.0, start + n / rate - time.monotonic()))
    time.sleep(1.0)
    credits = supplier._topics["Tick"].credits
    stalls = 0 if credits is None else credits.flow.stalls
    say("SENT", supplier.sent, supplier.dropped, stalls, supplier.waited)
    for line in sys.stdin:
        if line.strip() == "PUSH":  # one more: a consumer sees what it missed before it
            supplier.push("Tick", Miro.TimeIDL(count, 0))
            count += 1
            time.sleep(0.5)
            say("SENT", supplier.sent, supplier.dropped)
    server.shutdown()


def count(naming: str, channel_name: str, depth: int, topics: int = 1) -> None:
    server = Server(["counter", "--naming", naming, "-MNC", "c"])
    c = StructuredPushConsumer(server.resolve_channel(channel_name), depth=depth)
    c.set_subscriptions([("s", t) for t in TYPES[:topics]])
    threading.Thread(target=server.run, daemon=True).start()
    say("READY")
    for line in sys.stdin:
        if line.strip() == "STATS":
            say("STATS", c.received, c.missed, c.dropped)
    server.shutdown()


if __name__ == "__main__":
    role, naming, channel_name = sys.argv[1:4]
    rest = sys.argv[4:]
    os.environ.setdefault("MIRO_LOG_LEVEL", "warning")
    if role == "flood":
        rate = float(rest[1]) if len(rest) > 1 else 0.0
        keep_all = int(rest[2]) if len(rest) > 2 else 0
        topics = int(rest[3]) if len(rest) > 3 else 1
        flood(naming, channel_name, int(rest[0]), rate, keep_all, topics)
    elif role == "count":
        count(
            naming, channel_name, int(rest[0]) if rest else 0, int(rest[1]) if len(rest) > 1 else 1
        )
    elif role == "supply":
        pace = float(rest[2]) if len(rest) > 2 else 0.0
        supply(naming, channel_name, int(rest[0]), int(rest[1]), pace)
    else:
        consume(naming, channel_name, int(rest[0]), float(rest[1]), "zero-copy" in rest)
