"""The GPS driver: an NMEA 0183 receiver on a serial port, in the manual's Publish Server and
Reactor shape (§7.5), and a template for new drivers.

    python services/gps [-MCF robot.xml] [--device PATH] [--baud N] [common options]
    miro sim nmea --link /tmp/gps0 &  python services/gps --device /tmp/gps0

Its parameters (services/gps/GpsParameters.xml, compiled into Miro.GpsParameters: device, serial
settings, object, channel and event names, getWaitData's timeout) come from the run-time document
(`-MCF FILE`, else `<hostname>.xml`), section "Gps", category "Gps" (services/gps/etc/gps.xml is
an example); `--device` and `--baud` override the document, for a quick start.

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
from Miro.GpsParameters import GpsParameters
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
from miro_gen.params import ParamsError, live, read_parameters
from miro_gen.transport.options import UsageError

_log = log.logger("GPS")


class GpsImpl(Miro__POA.Gps, Implementation[Miro.GpsDataIDL]):
    """Miro::Gps: the latest reading, or the next one."""

    def __init__(self, supplier: StructuredPushSupplier | None, params: GpsParameters) -> None:
        Implementation.__init__(
            self,
            supplier,
            params.eventName,
            initial=NmeaParser().reading,
            timeout=params.waitTimeout.total_seconds(),
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


def main(argv: list[str] | None = None) -> int:
    try:
        server = Server(sys.argv if argv is None else argv)
    except UsageError as e:
        print(f"gps: {e}", file=sys.stderr)
        return 2
    p = argparse.ArgumentParser(prog="gps", description=__doc__.split("\n\n")[0])
    p.add_argument("--device", help="serial port or pyserial URL (overrides the document)")
    p.add_argument("--baud", type=int, help="baud rate (overrides the document)")
    args = p.parse_args(server.argv[1:])
    params = GpsParameters.instance()
    try:
        read_parameters(params, "Gps", config_file=server.options.config_file)
    except ParamsError as e:
        print(f"gps: {e}", file=sys.stderr)
        return 1
    if args.device:
        params.device = args.device
    if args.baud:
        params.ttyParams.baudrate = args.baud
    _log.debug("parameters:\n%s", params)
    try:
        supplier = StructuredPushSupplier(
            EventChannelFactory(server).find_or_create_channel(params.channelName)
        )
    except SystemException as e:
        print(f"gps: {e}", file=sys.stderr)
        return 1
    impl = GpsImpl(supplier, params)

    def follow(_: object) -> None:  # `miro param set`: the new values take effect at once
        impl.timeout = params.waitTimeout.total_seconds()
        impl.type_name = params.eventName

    live.on_change(follow)
    consumer = NmeaConsumer(impl)
    framer = DelimitedFramer(b"$", b"\n", max_length=256)  # NMEA: at most 82 characters
    handler = DevEventHandler(framer, consumer)
    settings = params.ttyParams.pyserial()
    connection = TtyConnection(server.reactor(), handler, params.device, settings)
    server.add_to_name_service(impl, params.objectName)
    connection.open()
    print(
        f"gps: reading {params.device}, serving {params.objectName}, "
        f"publishing {params.eventName} on {params.channelName}",
        flush=True,
    )
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
