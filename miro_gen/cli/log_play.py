"""`miro log play`: Miro's LogPlayer, replaying an MCAP file into a channel."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import (
    COMMON,
    make_server,
    open_log,
    read_status,
    split_common,
    topic_arg,
)


def play_main(argv: Sequence[str]) -> int:
    prog = "miro log play"
    p = argparse.ArgumentParser(
        prog=prog,
        description="Replay a log into a channel: every event at its log time (scaled by "
        "--rate), with its recorded domain, type, sequence number and source stamp. On a "
        "terminal: space pauses and resumes, s steps one event, q quits. Hosts the channel "
        "if nobody has it bound. " + COMMON,
    )
    p.add_argument("file", help="an MCAP file written by miro log record")
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    p.add_argument(
        "--clock-channel",
        default="LogClock",
        metavar="NAME",
        help="the channel, hosted here, where the log clock is published for processes on "
        "--clock log (default LogClock)",
    )
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    p.add_argument("--loop", action="store_true", help="start again at the end")
    p.add_argument("--start", type=float, default=0.0, metavar="S", help="from S s into the log")
    p.add_argument("--end", type=float, metavar="E", help="up to E s into the log")
    p.add_argument(
        "--topics", nargs="+", type=topic_arg, metavar="TOPIC", help="DOMAIN/TYPE (default all)"
    )
    p.add_argument(
        "--wait",
        type=float,
        default=0.5,
        metavar="S",
        help="seconds to let consumers connect before the first event (default 0.5)",
    )
    ns = p.parse_args(split_common(p, argv))
    if not ns.rate > 0:
        p.error("--rate must be more than 0")
    if ns.start < 0 or (ns.end is not None and ns.end < ns.start):
        p.error("--start must be 0 or more, and --end not before it")
    from miro_gen.eventlog.reader import LogError

    log = open_log(ns.file)
    if log is None:
        return 1
    with log:
        try:
            log.span()  # reads an unfinished file through: faults show before anything plays
        except LogError as e:
            print(f"{ns.file}: error: {e}", file=sys.stderr)
            return 1
        return _run(p, prog, argv, ns, log)


def _run(p: argparse.ArgumentParser, prog: str, argv: Sequence[str], ns: Any, log: Any) -> int:
    import threading

    import MiroNaming

    from miro_gen.eventlog.keys import key_presses
    from miro_gen.eventlog.player import Player, PlayOptions
    from miro_gen.eventlog.progress import StatusLine, bar
    from miro_gen.eventlog.reader import LogError
    from miro_gen.eventlog.replay import ReplaySupplier
    from miro_gen.exceptions import SystemException
    from miro_gen.transport.events import EventChannelFactory, StructuredPushSupplier

    # Hand the interpreter between the player's thread and the reactor's within 0.5 ms, not
    # Python's default 5 ms: a replayed event must leave on time.
    sys.setswitchinterval(0.0005)
    server = make_server(p, prog, argv)
    try:
        try:
            channel = server.resolve_channel(ns.channel)
        except MiroNaming.NotFound:
            channel = EventChannelFactory(server).create_channel(ns.channel)
    except SystemException as e:
        print(f"{prog}: {server.options.naming}: {e}", file=sys.stderr)
        server.close()
        return 1
    supplier = ReplaySupplier(channel)
    clock_channel = EventChannelFactory(server).create_channel(ns.clock_channel)
    options = PlayOptions(ns.rate, ns.loop, ns.start, ns.end, ns.topics)
    reactor_thread = threading.Thread(target=server.run, name="miro-reactor", daemon=True)
    reactor_thread.start()
    status = StatusLine()
    try:
        player = Player(log, supplier, options, StructuredPushSupplier(clock_channel))
    except LogError as e:
        server.shutdown()
        reactor_thread.join(5)
        print(f"{ns.file}: error: {e}", file=sys.stderr)
        return 1
    span = max(1, (player.end_ns or player.last_ns) - player.begin_ns)
    shown = [0.0]

    def progress(pl: Player, force: bool = False) -> None:
        now = time.monotonic()
        if now - shown[0] < 0.1 and not force:
            return
        shown[0] = now
        at = pl.log_now() - pl.begin_ns
        state = " paused (space: resume, s: step)" if pl.paused else ""
        status.update(
            f"{bar(at / span)} {at / 1e9:8.2f}/{span / 1e9:.2f} s  {pl.sent} events  "
            f"x{pl.rate:g}{state}"
        )

    player.on_progress = progress

    def on_key(ch: str) -> None:
        if ch == " ":
            player.toggle()
        elif ch in "sS.":
            player.step()
        elif ch in "qQ":
            player.stop()
        progress(player, force=True)

    signal.signal(signal.SIGTERM, lambda *_: player.stop())
    print(f"playing {ns.file} into {channel.name} at x{ns.rate:g}", file=sys.stderr)
    error = None
    time.sleep(max(0.0, ns.wait))
    try:
        with key_presses(on_key):
            player.play()
    except LogError as e:
        error = str(e)
    except KeyboardInterrupt:
        player.stop()
    finally:
        time.sleep(0.2)  # let the last frames leave
        server.shutdown()
        reactor_thread.join(5)
    status.done(f"{ns.file}: replayed {player.sent} events into {channel.name}")
    return read_status(ns.file, log, error)
