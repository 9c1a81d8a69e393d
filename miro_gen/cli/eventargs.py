"""What the event-log commands share: topic arguments, the common options, a server, the
event channel (waited for), opening a log, how long sequences are shown."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from typing import Any

# The options' and topics' modules are imported where they are used: `miro log info` and
# `miro log echo` use neither, and their start-up is the figure of a command that reads a
# summary (bench/bench_logplayer.py).

COMMON = "Accepts the common options (--naming tcp://HOST:PORT, -MNC NAME, -MLL N, --host ADDR)."


def add_length_options(p: argparse.ArgumentParser) -> None:
    """-l/--truncate-length and -f/--full-length, as `ros2 topic echo` has them."""
    from miro_gen.eventlog.show import TRUNCATE

    p.add_argument(
        "-l",
        "--truncate-length",
        type=int,
        default=TRUNCATE,
        metavar="N",
        help="show a sequence or byte string of more than N elements as its length and first N "
        f"(default {TRUNCATE})",
    )
    p.add_argument(
        "-f", "--full-length", action="store_true", help="show sequences and byte strings whole"
    )


def length_limit(p: argparse.ArgumentParser, ns: argparse.Namespace) -> int | None:
    """The elements shown of a long sequence (None: all), from add_length_options' options."""
    if ns.truncate_length < 0:
        p.error("--truncate-length must be 0 or more")
    return None if ns.full_length else int(ns.truncate_length)


def topic_arg(text: str) -> tuple[str, str]:
    from miro_gen.eventlog.types import parse_topic

    try:
        return parse_topic(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def split_common(p: argparse.ArgumentParser, argv: Sequence[str]) -> list[str]:
    """The arguments left after the common options (checked here, so that a bad one is a
    usage error before any socket exists)."""
    from miro_gen.service.options import UsageError, parse_common_options

    try:
        _, rest = parse_common_options(list(argv))
    except UsageError as e:
        p.error(str(e))
    return rest


def make_server(p: argparse.ArgumentParser, prog: str, argv: Sequence[str]) -> Any:
    from miro_gen.service.options import UsageError
    from miro_gen.service.server import Server

    try:
        return Server([prog, *argv])
    except UsageError as e:
        p.error(str(e))


def resolve_or_wait(server: Any, name: str, prog: str) -> Any:
    """The channel `name`; waits for it to be bound (a recorder may start before the robot)."""
    import MiroNaming

    from miro_gen.exceptions import SystemException

    told = False
    while True:
        try:
            return server.resolve_channel(name)
        except (MiroNaming.NotFound, SystemException) as e:
            if not told:
                why = f"{e.name} is not bound" if isinstance(e, MiroNaming.NotFound) else str(e)
                print(f"{prog}: waiting for the event channel {name} ({why})", file=sys.stderr)
                told = True
            time.sleep(0.5)


def server_and_channel(
    p: argparse.ArgumentParser, prog: str, argv: Sequence[str], name: str
) -> tuple[Any, Any] | None:
    """A Server for a live tool and the channel `name`, waited for; None when Ctrl-C comes
    first (the server is closed then)."""
    server = make_server(p, prog, argv)
    try:
        return server, resolve_or_wait(server, name, prog)
    except KeyboardInterrupt:
        server.close()
        return None


def open_log(path: str) -> Any:
    from miro_gen.cli.log_ros2 import log_file
    from miro_gen.eventlog.reader import LogError, LogReader

    try:
        return LogReader(log_file(path))
    except LogError as e:
        print(f"{path}: error: {e}", file=sys.stderr)
        return None


def read_status(path: str, log: Any, error: object) -> int:
    """The exit status of a tool that read the log at `path`: 1 after a reading `error` (said),
    else 0, with a warning when the file is unfinished."""
    if error is not None:
        print(f"{path}: error: {error}", file=sys.stderr)
        return 1
    log_warning(path, log)
    return 0


def log_warning(path: str, log: Any) -> None:
    """Warn about an unfinished file, or one whose summary is damaged."""
    if log.warning is not None:
        print(f"{path}: warning: {log.warning}", file=sys.stderr)
