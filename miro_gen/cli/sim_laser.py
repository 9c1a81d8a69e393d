"""`miro sim laser`: a laser scanner publishing scans on an event channel (miro_gen.sim.laser)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

PROG = "miro sim laser"
DOC = (
    "Publish the scans of a simulated laser scanner (a room with a pillar going to and fro) as "
    "Miro::RangeScanEventIDL events on an event channel, at the scanner's rate: by default a "
    "UTM-30LX, 1,081 beams over 270 degrees at 40 Hz. Accepts the common options (--naming "
    "tcp://HOST:PORT, -MNC NAME: the events' domain, -MLL N, --host ADDR)."
)


def _options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--beams", type=int, default=1081, help="beams over 270 degrees (1081)")
    p.add_argument("--rate", type=float, default=40.0, help="scans a second (default 40)")
    p.add_argument("--type", default="Laser", help="the events' type name (default Laser)")
    p.add_argument("--channel", default="EventChannel", help="default EventChannel")
    p.add_argument("--duration", type=float, default=0, help="stop after S seconds")


def laser_main(argv: Sequence[str]) -> int:
    from miro_gen.devices.startup import fail, start, supplier_on
    from miro_gen.sim.laser import LaserPublisher, LaserScans

    server, args = start(PROG, [PROG, *argv], DOC, _options)
    if args.beams < 2 or args.rate <= 0 or args.duration < 0:
        fail(PROG, "--beams must be 2 or more, --rate above 0, --duration not negative", 2)
    publisher = LaserPublisher(
        supplier_on(server, args.channel, PROG), LaserScans(args.beams, args.rate), args.type
    )
    reactor = server.reactor()
    reactor.schedule_timer(0.0, 1.0 / args.rate, publisher)
    if args.duration:
        reactor.schedule_timer(args.duration, 0.0, lambda _: server.shutdown())
    domain = server.options.naming_context
    print(
        f"laser: {args.beams} beams at {args.rate:g} Hz as {domain}/{args.type} on "
        f"{args.channel} (Ctrl-C to stop)",
        flush=True,
    )
    server.run()
    unheard = publisher.taken - publisher.published
    print(
        f"published {publisher.published} scans ({unheard} taken while nobody subscribed)",
        flush=True,
    )
    return 0
