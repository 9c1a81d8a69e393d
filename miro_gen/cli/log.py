"""`miro log record|play|player|info|echo|cut|merge`: Miro's LogNotify, LogPlayer and
LogTruncate on MCAP files; this module dispatches them and holds info and echo."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import (
    log_warning,
    open_log,
    piped,
    read_status,
    topic_arg,
)


def main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log",
        description="Record event channels into MCAP files, replay them, and look into them.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name, text in (
        ("record", "record events of a channel into an MCAP file (Miro's LogNotify)"),
        ("play", "replay logs into each robot's channel with their original timing (LogPlayer)"),
        ("player", "the player's window: play, seek, step, cut, plot (Miro's LogPlayer GUI)"),
        ("info", "summarise a log: topics, types, counts, time span, rates"),
        ("echo", "print the events of a log, decoded"),
        ("cut", "write part of a log to a new one, or repair a log (Miro's LogTruncate)"),
        ("merge", "merge logs into one, in log-time order"),
    ):
        sub.add_parser(name, help=text, add_help=False)
    args = list(argv)
    run = {
        "record": _record,
        "play": _play,
        "player": _player,
        "info": info_main,
        "echo": echo_main,
        "cut": _cut,
        "merge": _merge,
    }
    if args and args[0] in run:
        return piped(run[args[0]], args[1:])
    ns = p.parse_args(args)
    if ns.command is None:
        p.print_help()
        return 0
    return 0  # pragma: no cover


def info_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log info",
        description="Summarise an event log: topics, types, counts, time span and rates.",
    )
    p.add_argument("file", help="an MCAP file")
    ns = p.parse_args(argv)
    from miro_gen.eventlog.reader import LogError
    from miro_gen.eventlog.show import date_text

    log = open_log(ns.file)
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
    state = "finished"
    if log.unfinished or log.damaged_summary:
        state = "unfinished (no summary)" if log.unfinished else "summary damaged"
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
        # n events over the span are n - 1 periods (and one event has no rate)
        rate = f"{(n - 1) / duration:10.2f} Hz" if duration > 0 and n > 1 else ""
        print(
            f"  {t.topic:<{width}}  {t.schema_name or '(no schema)':<{type_width}}  "
            f"{n:8d} events{rate}  hash {t.type_hash[:12]}"
        )
    return read_status(ns.file, log, error)


def _compile_missing_types(path: str, log: Any) -> None:
    """Compile the log's schemas whose types are not generated here, so that they decode."""
    from miro_gen.eventlog.types import types_from_schemas
    from miro_gen.runtime import registry

    missing = [
        t
        for t in log.topics()
        if t.schema_encoding == "omgidl" and t.type_hash and registry.find(t.type_hash) is None
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

    log = open_log(ns.file)
    if log is None:
        return 1
    shown = 0
    with log:
        if ns.topics and not _matching_topics(ns.file, log, ns.topics):
            return 1
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
    log_warning(ns.file, log)
    return 0


def _matching_topics(path: str, log: Any, wanted: list[tuple[str, str]]) -> bool:
    """Whether any topic of the log matches `wanted`; if not, say so and list its topics. A
    pattern that matches none of them while others do is a warning."""
    from miro_gen.eventlog.types import matches

    topics = sorted({t.topic: (t.domain, t.type_name) for t in log.topics()}.items())
    unmatched = [
        f"{domain}/{type_name}"
        for domain, type_name in wanted
        if not any(matches((domain, type_name), *parts) for _, parts in topics)
    ]
    if len(unmatched) < len(wanted):
        for pattern in unmatched:
            print(f"{path}: warning: no topic matches {pattern}", file=sys.stderr)
        return True
    names = ", ".join(name for name, _ in topics) or "none"
    print(
        f"{path}: no topic matches {', '.join(unmatched)}; the log's topics: {names}",
        file=sys.stderr,
    )
    return False


def _record(argv: Sequence[str]) -> int:
    from miro_gen.cli.log_record import record_main

    return record_main(argv)


def _play(argv: Sequence[str]) -> int:
    from miro_gen.cli.log_play import play_main

    return play_main(argv)


def _player(argv: Sequence[str]) -> int:
    from miro_gen.cli.log_player import player_main

    return player_main(argv)


def _cut(argv: Sequence[str]) -> int:
    from miro_gen.cli.log_edit import cut_main

    return cut_main(argv)


def _merge(argv: Sequence[str]) -> int:
    from miro_gen.cli.log_edit import merge_main

    return merge_main(argv)
