"""The GPS driver: an NMEA 0183 receiver on a serial port, in the manual's Publish Server and
Reactor shape (§7.5), and a template for new drivers.

    python services/gps [-MCF robot.xml] [--device PATH] [--baud N] [common options]
    miro run gps [...]                  (the same, from an installed miro-gen)
    miro sim nmea --link /tmp/gps0 &  python services/gps --device /tmp/gps0

Its parameters (services/gps/GpsParameters.xml, compiled into Miro.GpsParameters: device, serial
settings, object, channel and event names, getWaitData's timeout, the date rules) come from the
run-time document
(`-MCF FILE`, else `<hostname>.xml`), section "Gps", category "Gps" (services/gps/etc/gps.xml is
an example); `--device` and `--baud` override the document, for a quick start.

The pieces, each replaceable when writing another driver:
- Connection: `TtyConnection` (any pyserial URL) on the server's reactor, reopened when the
  device comes back;
- EventHandler: `DevEventHandler` with a `DelimitedFramer` cutting `$...\\r\\n` sentences out of
  whatever the reads return;
- Consumer: `NmeaConsumer.handle_message` parses a sentence (services/gps/nmea.py decodes it,
  services/gps/nmea_epochs.py puts the sentences of one fix together) and hands each completed
  reading, one per fix, to the Implementation; a reactor timer completes the last fix when the
  receiver falls silent;
- Implementation: `GpsImpl`, the runtime's `Implementation` base: `integrate_data` keeps the
  latest reading for `getData`, wakes `getWaitData` callers and publishes a `Gps` event.
The handler and the consumer run on the reactor thread; `getWaitData` blocks a worker, never the
reactor. On exit it prints what it read: good, ignored and bad sentences, and noise bytes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script (python services/gps): the generated code
    _here = Path(__file__).resolve().parent  # beside the checkout, and this folder as the
    sys.path[:0] = [str(_here.parents[1] / "generated"), str(_here.parent)]  # package it is
    __package__ = _here.name  # (as `python -m services.gps` and `miro run gps` import it)

import Miro
import Miro__POA
from Miro.GpsParameters import GpsParameters
from miro_gen import (
    Implementation,
    StructuredPushSupplier,
    log,
    nonblocking,
)
from miro_gen.devices import (
    DelimitedFramer,
    DevConsumer,
    DevEventHandler,
    DevMessage,
    SubscriberNotice,
    TtyConnection,
    startup,
)
from miro_gen.params.runtime import live

from .nmea_epochs import NmeaParser, parse_date

_log = log.logger("GPS")

QUIET = 0.25  # seconds of silence after which the receiver has said all about its last fix


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
    """Sentences in, readings (one per fix) out to the Implementation."""

    def __init__(self, impl: GpsImpl, parser: NmeaParser) -> None:
        self.impl = impl
        self.parser = parser
        self.last_input = 0.0  # host time of the last sentence
        self.subscribers = SubscriberNotice(impl.supplier, impl.type_name, "readings")

    def handle_message(self, message: DevMessage) -> None:
        self.last_input = time.time()
        for reading in self.parser.feed(message.data, message.stamp):
            self.impl.integrate_data(reading, message.stamp)

    def handle_timeout(self, _arg: object) -> None:
        """Every QUIET / 2 seconds on the reactor: a receiver silent for QUIET has finished its
        fix, even if its last sentence was not the usual last one. Also notes when the first
        subscriber comes and the last one goes."""
        if self.last_input and time.time() - self.last_input >= QUIET:
            self.last_input = 0.0
            for reading in self.parser.flush():
                self.impl.integrate_data(reading, time.time())
        self.subscribers.check()

    def connection_changed(self, connected: bool) -> None:
        _log.notice("receiver %s", "connected" if connected else "lost")


def options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", help="serial port or pyserial URL (overrides the document)")
    p.add_argument("--baud", type=int, help="baud rate (overrides the document)")


def main(argv: list[str] | None = None) -> int:
    server, args = startup.start("gps", argv, __doc__, options)
    params = GpsParameters.instance()
    startup.read(params, "Gps", server, "gps")
    if args.device:
        params.device = args.device
    if args.baud:
        params.ttyParams.baudrate = args.baud
    try:
        not_before = parse_date(params.dateNotBefore)
    except ValueError as e:
        startup.fail("gps", f"DateNotBefore: {e}")
    _log.debug("parameters:\n%s", params)
    supplier = startup.supplier_on(server, params.channelName, "gps")
    impl = GpsImpl(supplier, params)

    def follow(_: object) -> None:  # `miro param set`: the new values take effect at once
        impl.timeout = params.waitTimeout.total_seconds()
        impl.type_name = params.eventName

    live.on_change(follow)
    consumer = NmeaConsumer(impl, NmeaParser(not_before, params.hostDate))
    framer = DelimitedFramer(b"$", b"\n", max_length=256)  # NMEA: at most 82 characters
    handler = DevEventHandler(framer, consumer)
    settings = params.ttyParams.pyserial()
    connection = TtyConnection(server.reactor(), handler, params.device, settings)
    server.add_to_name_service(impl, params.objectName)
    server.reactor().schedule_timer(QUIET / 2, QUIET / 2, consumer)
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
        f"{impl.count} readings, {impl.published} published"
        + (
            f", {consumer.parser.rollovers} dates after a week rollover"
            if consumer.parser.rollovers
            else ""
        ),
        flush=True,
    )
    return 0


if __name__ == "__main__":
    run_main(main, "gps")
