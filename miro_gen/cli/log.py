"""`miro log record|play|info|echo`: Miro's LogNotify and LogPlayer on MCAP files."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from collections.abc import Sequence
from typing import Any

from miro_gen.eventlog.types import parse_topic
from miro_gen.transport.options import UsageError, parse_common_options

COMMON = "Accepts the common options (--naming tcp://HOST:PORT, -MNC NAME, -MLL N, --host ADDR)."


def main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log",
        description="Record event channels into MCAP files, replay them, and look into them.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name, text in (
        ("record", "record events of a channel into an MCAP file (Miro's LogNotify)"),
        ("play", "replay a log into a channel with its original timing (Miro's LogPlayer)"),
        ("info", "summarise a log: topics, types, counts, time span, rates"),
        ("echo", "print the events of a log, decoded"),
    ):
        sub.add_parser(name, help=text, add_help=False)
    args = list(argv)
    if args and args[0] in ("record", "play", "info", "echo"):
        run = {"record": record_main, "play": play_main, "info": info_main, "echo": echo_main}
        return piped(run[args[0]], args[1:])
    ns = p.parse_args(args)
    if ns.command is None:
        p.print_help()
        return 0
    return 0  # pragma: no cover


def piped(command: Any, argv: Sequence[str]) -> int:
    """Run `command(argv)`; a reader that went away (`| head`) ends it quietly."""
    try:
        return int(command(argv))
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so that the exit's flush does not fail again
        return 0


def topic_arg(text: str) -> tuple[str, str]:
    try:
        return parse_topic(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def split_common(p: argparse.ArgumentParser, argv: Sequence[str]) -> list[str]:
    """The arguments left after the common options (checked here, so that a bad one is a
    usage error before any socket exists)."""
    try:
        _, rest = parse_common_options(list(argv))
    except UsageError as e:
        p.error(str(e))
    return rest


def make_server(p: argparse.ArgumentParser, prog: str, argv: Sequence[str]) -> Any:
    from miro_gen.transport.server import Server

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


# ---- record ---------------------------------------------------------------------------------


def record_main(argv: Sequence[str]) -> int:
    prog = "miro log record"
    p = argparse.ArgumentParser(
        prog=prog,
        description="Record the events of a channel into an MCAP file, a channel per "
        "DOMAIN/TYPE topic, until Ctrl-C (or SIGTERM), which finishes the file. " + COMMON,
    )
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="the MCAP file")
    p.add_argument("-f", "--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    p.add_argument(
        "topics",
        nargs="*",
        type=topic_arg,
        metavar="TOPIC",
        help="DOMAIN/TYPE to record, * for any part (robot1/*, */Odometry); default all",
    )
    ns = p.parse_args(split_common(p, argv))
    if os.path.exists(ns.output) and not ns.force:
        p.error(f"{ns.output} exists (use --force to overwrite it)")
    from miro_gen.eventlog.progress import StatusLine
    from miro_gen.eventlog.recorder import Recorder
    from miro_gen.eventlog.writer import LogWriter

    server = make_server(p, prog, argv)
    try:
        writer = LogWriter(ns.output)
    except OSError as e:
        print(f"{ns.output}: error: cannot write: {e.strerror or e}", file=sys.stderr)
        server.close()
        return 1
    status = StatusLine()
    try:
        channel = resolve_or_wait(server, ns.channel, prog)
    except KeyboardInterrupt:
        writer.finish()
        server.close()
        status.done(f"{ns.output}: 0 events (stopped before {ns.channel} was bound)")
        return 130
    subs = ns.topics or [("*", "*")]
    recorder = Recorder(server, channel, subs, writer, status)
    shown = " ".join(f"{d}/{t}" for d, t in subs)
    print(f"recording {shown} from {channel.name} into {ns.output}", file=sys.stderr)
    recorder.run()
    for topic, type_hash in sorted(writer.unknown_types):
        print(
            f"{prog}: warning: {topic}: no generated type here has the type hash "
            f"{type_hash[:12]}; recorded without a schema (Foxglove cannot decode it)",
            file=sys.stderr,
        )
    missed = f", {recorder.tap.missed} missed (sequence gaps)" if recorder.tap.missed else ""
    status.done(
        f"{ns.output}: {writer.messages} events{missed} in "
        f"{time.monotonic() - recorder.started:.1f} s"
    )
    return 0


# ---- info and echo --------------------------------------------------------------------------


def _open(path: str) -> Any:
    from miro_gen.eventlog.reader import LogError, LogReader

    try:
        return LogReader(path)
    except LogError as e:
        print(f"{path}: error: {e}", file=sys.stderr)
        return None


def _unfinished_warning(path: str) -> None:
    print(
        f"{path}: warning: the file is unfinished (no summary: its recorder was killed?); "
        "read up to its last complete chunk",
        file=sys.stderr,
    )


def info_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log info",
        description="Summarise an event log: topics, types, counts, time span and rates.",
    )
    p.add_argument("file", help="an MCAP file")
    ns = p.parse_args(argv)
    from miro_gen.eventlog.reader import LogError
    from miro_gen.eventlog.show import date_text

    log = _open(ns.file)
    if log is None:
        return 1
    counts: dict[int, int] = {}
    first = last = None
    error = None
    with log:
        if log.summary is not None and log.summary.statistics is not None:
            stats = log.summary.statistics
            counts = dict(stats.channel_message_counts)
            if stats.message_count:
                first, last = stats.message_start_time, stats.message_end_time
        else:
            try:
                for topic, message in log.messages():
                    counts[topic.id] = counts.get(topic.id, 0) + 1
                    t = message.log_time
                    first = t if first is None else min(first, t)
                    last = t if last is None else max(last, t)
            except LogError as e:
                error = str(e)
        topics = log.topics()
    total = sum(counts.values())
    duration = (last - first) / 1e9 if first is not None and last is not None else 0.0
    state = "unfinished (no summary)" if log.unfinished else "finished"
    print(f"file:      {ns.file} ({state})")
    print(f"events:    {total}")
    if first is not None and last is not None:
        print(f"start:     {date_text(first)} ({first / 1e9:.9f})")
        print(f"end:       {date_text(last)} ({last / 1e9:.9f})")
        print(f"duration:  {duration:.3f} s")
    print(f"topics:    {len(topics)}")
    width = max((len(t.topic) for t in topics), default=0)
    type_width = max((len(t.schema_name or "(no schema)") for t in topics), default=0)
    for t in topics:
        n = counts.get(t.id, 0)
        rate = f"{n / duration:10.2f} Hz" if duration > 0 else ""
        print(
            f"  {t.topic:<{width}}  {t.schema_name or '(no schema)':<{type_width}}  "
            f"{n:8d} events{rate}  hash {t.type_hash[:12]}"
        )
    if error is not None:
        print(f"{ns.file}: error: {error}", file=sys.stderr)
        return 1
    if log.unfinished:
        _unfinished_warning(ns.file)
    return 0


def _compile_missing_types(path: str, log: Any) -> None:
    """Compile the log's schemas whose types are not generated here, so that they decode."""
    from miro_gen.eventlog.types import find_type, types_from_schemas

    missing = [
        t
        for t in log.topics()
        if t.schema_encoding == "omgidl" and t.type_hash and find_type(t.type_hash) is None
    ]
    if missing:
        why = types_from_schemas([t.schema.decode("utf-8", "replace") for t in missing])
        if why is not None:
            names = ", ".join(t.topic for t in missing)
            print(f"{path}: warning: cannot decode {names}: {why}", file=sys.stderr)


def echo_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log echo",
        description="Print the events of a log, decoded with the generated types here.",
    )
    p.add_argument("file", help="an MCAP file")
    p.add_argument(
        "topics", nargs="*", type=topic_arg, metavar="TOPIC", help="DOMAIN/TYPE (default all)"
    )
    p.add_argument("-n", "--count", type=int, default=0, help="stop after N events")
    ns = p.parse_args(argv)
    from miro_gen.eventlog.reader import LogError
    from miro_gen.eventlog.show import clock_text, payload_text
    from miro_gen.eventlog.types import matches

    log = _open(ns.file)
    if log is None:
        return 1
    shown = 0
    with log:
        try:
            _compile_missing_types(ns.file, log)
            for topic, message in log.messages():
                if ns.topics and not any(
                    matches(f, topic.domain, topic.type_name) for f in ns.topics
                ):
                    continue
                text = payload_text(topic.type_hash, message.data)
                print(f"{clock_text(message.log_time)} {topic.topic} #{message.sequence} {text}")
                shown += 1
                if ns.count and shown >= ns.count:
                    break
        except LogError as e:
            sys.stdout.flush()
            print(f"{ns.file}: error: {e}", file=sys.stderr)
            return 1
    if log.unfinished:
        _unfinished_warning(ns.file)
    return 0


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

    log = _open(ns.file)
    if log is None:
        return 1
    with log:
        try:
            log.span()  # reads an unfinished file through: faults show before anything plays
        except LogError as e:
            print(f"{ns.file}: error: {e}", file=sys.stderr)
            return 1
        return _play(p, prog, argv, ns, log)


def _play(p: argparse.ArgumentParser, prog: str, argv: Sequence[str], ns: Any, log: Any) -> int:
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
    if error is not None:
        print(f"{ns.file}: error: {error}", file=sys.stderr)
        return 1
    if log.unfinished:
        _unfinished_warning(ns.file)
    return 0
