"""Timed event publication (the manual's §7.6): turns GPS readings, arriving at whatever rate,
into robot positions published at a fixed rate from a reactor timer. A template for filters.

    python services/gps_position.py [--rate HZ] [--domain D] [common options]

It subscribes to `Gps` events (type Miro::GpsDataIDL) and publishes `Position` events
(Miro::PositionIDL: millimetres east and north of the first valid fix, heading counter-clockwise
from east in radians, from the course over ground) RATE times a second while its latest fix is
fresh. The consumer's callback and the timer both run on the reactor thread, so the latest fix
needs no mutex (the manual's C++ version needed one).
"""

from __future__ import annotations

import math
import sys
import time
from functools import partial
from pathlib import Path
from typing import Any

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro
from miro_gen import (
    EventChannelFactory,
    Server,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)
from miro_gen.service.options import service_parser
from miro_gen.transport.events import EventChannel

EARTH_RADIUS = 6_371_000.0  # metres
STALE = 2.0  # seconds after which a fix is too old to publish


def position(fix: Miro.GpsDataIDL, origin: Miro.GpsDataIDL) -> Miro.PositionIDL:
    """`fix` in a local plane around `origin` (equirectangular: fine over a few kilometres)."""
    north = math.radians(fix.latitude - origin.latitude) * EARTH_RADIUS
    east = (
        math.radians(fix.longitude - origin.longitude)
        * EARTH_RADIUS
        * math.cos(math.radians(origin.latitude))
    )
    course = 0.0 if math.isnan(fix.course) else fix.course
    heading = math.remainder(math.radians(90.0 - course), 2 * math.pi)
    if heading == -math.pi:
        heading = math.pi
    return Miro.PositionIDL(Miro.WorldPointIDL(east * 1000, north * 1000), heading)


class GpsToPosition(StructuredPushConsumer):
    """Keeps the latest valid fix; the timer publishes it as a Position."""

    def __init__(self, channel: EventChannel, supplier: StructuredPushSupplier) -> None:
        super().__init__(channel)
        self.supplier = supplier
        self.origin: Miro.GpsDataIDL | None = None
        self.latest: Miro.GpsDataIDL | None = None
        self.received_at = 0.0
        self.published = 0

    def push_structured_event(self, event: StructuredEvent) -> None:
        fix = event.payload
        if not isinstance(fix, Miro.GpsDataIDL) or not fix.valid or math.isnan(fix.latitude):
            return
        if self.origin is None:
            self.origin = fix
        self.latest = fix
        self.received_at = time.monotonic()

    def handle_timeout(self, _: Any) -> None:
        if self.latest is None or self.origin is None:
            return
        if time.monotonic() - self.received_at > STALE:
            return
        stamp = self.latest.time.sec + self.latest.time.usec / 1e6
        if self.supplier.push("Position", position(self.latest, self.origin), stamp):
            self.published += 1


def main(argv: list[str] | None = None) -> int:
    server = Server(sys.argv if argv is None else argv)  # takes the common options out
    p = service_parser("gps_position", __doc__.split("\n\n")[0])
    p.add_argument("--rate", type=float, default=10.0, help="positions per second (default 10)")
    p.add_argument("--domain", default="*", help="the GPS's naming context (default: any)")
    p.add_argument("--channel", default="EventChannel", help="event channel (default EventChannel)")
    args = p.parse_args(server.argv[1:])
    if args.rate <= 0:
        p.error("--rate must be more than 0")
    channel = EventChannelFactory(server).find_or_create_channel(args.channel)
    filter_ = GpsToPosition(channel, StructuredPushSupplier(channel))
    filter_.set_subscriptions([(args.domain, "Gps")])
    server.reactor().schedule_timer(1 / args.rate, 1 / args.rate, filter_)
    ready = f"gps_position: Gps events in, Position events out at {args.rate:g} Hz"
    server.reactor().call_soon(partial(print, flush=True), ready)  # once it runs
    server.run()
    print(f"gps_position: {filter_.published} positions published", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "gps_position")
