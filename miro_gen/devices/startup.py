"""A driver's start-up, the same for every driver: the Server with the common options, the
driver's own options, its parameters from the run-time document, the event channel it publishes
on. A step that fails prints one line, `NAME: what went wrong`, and ends the process with Miro's
usual status (2 for a wrong command line, 1 for anything else): no traceback.

    server, args = start("laser", argv, __doc__, add_options)
    params = LaserParameters.instance()
    read(params, "Laser", server, "laser")
    supplier = supplier_on(server, params.channelName, "laser")
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn

from miro_gen.exceptions import SystemException
from miro_gen.params import Config, ParamsError, read_parameters
from miro_gen.service.options import UsageError, service_parser
from miro_gen.service.server import Server
from miro_gen.transport.events import EventChannelFactory, StructuredPushSupplier


def fail(name: str, message: object, status: int = 1) -> NoReturn:
    print(f"{name}: {message}", file=sys.stderr)
    raise SystemExit(status)


def start(
    name: str,
    argv: Sequence[str] | None,
    doc: str | None,
    options: Callable[[argparse.ArgumentParser], None] = lambda _: None,
) -> tuple[Server, argparse.Namespace]:
    """The Server (taking the common options out of `argv`, default sys.argv) and the driver's
    own options, which `options` adds to a parser described by `doc`'s first paragraph."""
    try:
        server = Server(list(sys.argv if argv is None else argv))
    except UsageError as e:
        fail(name, e, 2)
    parser = service_parser(name, (doc or "").split("\n\n")[0])  # --help: the common ones too
    options(parser)
    return server, parser.parse_args(server.argv[1:])


def read(params: Config, category: str, server: Server, name: str) -> None:
    """`params` from section and category `category` of the run-time document (`-MCF FILE`, else
    `<hostname>.xml`)."""
    try:
        read_parameters(params, category, config_file=server.options.config_file)
    except ParamsError as e:
        fail(name, e)


def supplier_on(server: Server, channel: str, name: str) -> StructuredPushSupplier:
    """A supplier on `channel`: the one bound in the naming context, else one this process hosts."""
    try:
        return StructuredPushSupplier(EventChannelFactory(server).find_or_create_channel(channel))
    except SystemException as e:
        fail(name, e)
