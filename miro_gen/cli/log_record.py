"""`miro log record`: Miro's LogNotify, recording a channel into an MCAP file."""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence

from miro_gen.cli.eventargs import (
    COMMON,
    make_server,
    resolve_or_wait,
    split_common,
    topic_arg,
)
from miro_gen.cli.log_ros2 import add_ros2_flag, record_ros2

SHOWN_UNKNOWN = 10  # topics without a generated type named one by one at the end


def record_main(argv: Sequence[str]) -> int:
    prog = "miro log record"
    p = argparse.ArgumentParser(
        prog=prog,
        description="Record the events of a channel into an MCAP file, a channel per "
        "DOMAIN/TYPE topic, until Ctrl-C (or SIGTERM), --count or --duration, which finishes "
        "the file. " + COMMON,
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="FILE",
        help="the MCAP file (default: CONTEXT_YYYY-MM-DD_HH-MM-SS.mcap, of the naming context "
        "and the time it starts, in $MIRO_LOG or else this folder)",
    )
    p.add_argument("-f", "--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    p.add_argument(
        "-n", "--count", type=_positive_int, default=0, metavar="N", help="stop after N events"
    )
    p.add_argument(
        "--duration",
        type=_positive_seconds,
        default=0.0,
        metavar="S",
        help="stop S seconds after recording starts",
    )
    p.add_argument(
        "topics",
        nargs="*",
        type=topic_arg,
        metavar="TOPIC",
        help="DOMAIN/TYPE to record, * for any part (robot1/*, */Odometry); default all",
    )
    add_ros2_flag(p)
    ns = p.parse_args(split_common(p, argv))
    if ns.output is not None and os.path.exists(ns.output) and not ns.force:
        p.error(f"{ns.output} exists (use --force to overwrite it)")
    if ns.ros2:
        if ns.count:
            p.error("--count is for Miro channels; with --ros2 use --duration or Ctrl-C")
        output = ns.output or default_output("ros2")
        return record_ros2(prog, output, ns.topics, duration=ns.duration)
    from miro_gen.eventlog.progress import StatusLine
    from miro_gen.eventlog.recorder import Recorder
    from miro_gen.eventlog.writer import LogWriter

    server = make_server(p, prog, argv)
    if ns.output is None:
        ns.output = default_output(server.options.naming_context)
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
    recorder = Recorder(server, channel, subs, writer, status, count=ns.count, duration=ns.duration)
    shown = " ".join(f"{d}/{t}" for d, t in subs)
    print(f"recording {shown} from {channel.name} into {ns.output}", file=sys.stderr)
    recorder.run()
    unknown = sorted(writer.unknown_types)
    for topic, type_hash in unknown[:SHOWN_UNKNOWN]:  # a peer may make up thousands
        print(
            f"{prog}: warning: {topic}: no generated type here has the type hash "
            f"{type_hash[:12]}; recorded without a schema (Foxglove cannot decode it)",
            file=sys.stderr,
        )
    if len(unknown) > SHOWN_UNKNOWN:
        print(
            f"{prog}: warning: {len(unknown) - SHOWN_UNKNOWN:,} more topics or type hashes "
            "without a generated type here, recorded without a schema",
            file=sys.stderr,
        )
    if writer.refused:
        print(
            f"{prog}: warning: {writer.refused} events of topics past the 65,535th not "
            f"recorded (an MCAP file numbers its channels with 16 bits), such as "
            f"{min(writer.refused_topics)}",
            file=sys.stderr,
        )
    missed = f", {recorder.tap.missed} missed (sequence gaps)" if recorder.tap.missed else ""
    status.done(
        f"{ns.output}: {writer.messages} events{missed} in "
        f"{time.monotonic() - recorder.started:.1f} s"
    )
    return 0


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive whole number")
    return n


def _positive_seconds(text: str) -> float:
    try:
        s = float(text)
    except ValueError:
        s = 0.0
    if not s > 0 or s == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return s


def default_output(context: str) -> str:
    """Where a recording goes when no file is named, as rosbag2 and Miro's LogNotify name
    theirs: `<context>_<date>_<time>.mcap` in $MIRO_LOG, else in the working folder (a
    number added when a recording of the same second is there already)."""
    folder = os.environ.get("MIRO_LOG") or "."
    stem = f"{context.replace('/', '-')}_{time.strftime('%Y-%m-%d_%H-%M-%S')}"
    path = os.path.join(folder, f"{stem}.mcap")
    n = 1
    while os.path.exists(path):
        n += 1
        path = os.path.join(folder, f"{stem}_{n}.mcap")
    return path
