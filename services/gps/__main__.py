"""The GPS driver: an NMEA 0183 receiver on a serial port, in the manual's Publish Server and
Reactor shape (§7.5), and a template for new drivers.

    python services/gps --device /dev/ttyUSB0 [--baud 4800] [common options]
    miro sim nmea --link /tmp/gps0 &  python services/gps --device /tmp/gps0

The pieces, each replaceable when writing another driver:
- Connection: `TtyConnection` (any pyserial URL) on the server's reactor, reopened when the
  device comes back;
- EventHandler: `DevEventHandler` with a `DelimitedFramer` cutting `$...\\r\\n` sentences out of
  whatever the reads return;
- Consumer: `NmeaConsumer.handle_message` parses a sentence (services/gps/nmea.py) and hands each
  completed reading to the Implementation;
- Implementation: `GpsImpl`, the runtime's `Implementation` base: `integrate_data` keeps the
  latest reading for `getData`, wakes `getWaitData` callers and publishes a `Gps` event.
The handler and the consumer run on the reactor thread; `getWaitData` blocks a worker, never the
reactor. On exit it prints what it read: good, ignored and bad sentences, and noise bytes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the generated code and this folder beside it
    here = Path(__file__).resolve().parent
    sys.path[:0] = [str(here.parents[1] / "generated"), str(here)]

import Miro
import Miro__POA
import MiroNaming
from nmea import NmeaParser

from miro_gen import (
    EventChannelFactory,
    Implementation,
    Server,
    StructuredPushSupplier,
    SystemException,
    log,
    nonblocking,
)
from miro_gen.devices import (
    DelimitedFramer,
    DevConsumer,
    DevEventHandler,
    DevMessage,
    TtyConnection,
)
from miro_gen.transport.events import EventChannel
from miro_gen.transport.options import UsageError

_log = log.logger("GPS")
EVENT = "Gps"


class GpsImpl(Miro__POA.Gps, Implementation[Miro.GpsDataIDL]):
    """Miro::Gps: the latest reading, or the next one."""

    def __init__(self, supplier: StructuredPushSupplier | None, timeout: float) -> None:
        Implementation.__init__(
            self, supplier, EVENT, initial=NmeaParser().reading, timeout=timeout
        )

    @nonblocking
    def getData(self) -> Miro.GpsDataIDL:
        return self.latest()

    def getWaitData(self) -> Miro.GpsDataIDL:
        return self.wait_next(Miro.ETimeOut)


class NmeaConsumer(DevConsumer):
    """Sentences in, readings out to the Implementation."""

    def __init__(self, impl: GpsImpl) -> None:
        self.impl = impl
        self.parser = NmeaParser()

    def handle_message(self, message: DevMessage) -> None:
        reading = self.parser.feed(message.data, message.stamp)
        if reading is not None:
            self.impl.integrate_data(reading, message.stamp)

    def connection_changed(self, connected: bool) -> None:
        _log.notice("receiver %s", "connected" if connected else "lost")


def channel_for(server: Server, name: str) -> EventChannel:
    """The event channel `name`: the one bound in naming if there is one, else hosted here."""
    try:
        channel: EventChannel = server.resolve_channel(name)
        return channel
    except MiroNaming.NotFound:
        return EventChannelFactory(server).create_channel(name)


def main(argv: list[str] | None = None) -> int:
    try:
        server = Server(sys.argv if argv is None else argv)
    except UsageError as e:
        print(f"gps: {e}", file=sys.stderr)
        return 2
    p = argparse.ArgumentParser(prog="gps", description=__doc__.split("\n\n")[0])
    p.add_argument("--device", required=True, help="serial port or pyserial URL of the receiver")
    p.add_argument("--baud", type=int, default=4800, help="baud rate (default 4800, NMEA's)")
    p.add_argument("--channel", default="EventChannel", help="event channel (default EventChannel)")
    p.add_argument("--name", default="Gps", help="name in the naming service (default Gps)")
    p.add_argument("--timeout", type=float, default=5.0, help="getWaitData's limit, s (default 5)")
    args = p.parse_args(server.argv[1:])
    try:
        supplier = StructuredPushSupplier(channel_for(server, args.channel))
    except SystemException as e:
        print(f"gps: {e}", file=sys.stderr)
        return 1
    impl = GpsImpl(supplier, args.timeout)
    consumer = NmeaConsumer(impl)
    framer = DelimitedFramer(b"$", b"\n", max_length=256)  # NMEA: at most 82 characters
    handler = DevEventHandler(framer, consumer)
    connection = TtyConnection(server.reactor(), handler, args.device, {"baudrate": args.baud})
    server.add_to_name_service(impl, args.name)
    connection.open()
    print(f"gps: reading {args.device}, serving {args.name}, publishing {EVENT}", flush=True)
    server.on_shutdown(connection.close)
    server.run()
    c = consumer.parser.counts
    print(
        f"gps: {c.good} sentences used, {c.ignored} ignored, {c.checksum} with a bad checksum, "
        f"{c.malformed} malformed, {framer.discarded} noise bytes; "
        f"{impl.count} readings, {impl.published} published",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
