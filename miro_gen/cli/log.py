"""`miro log info` and `miro log echo`, the two `miro log` sub-verbs that only read a file (the
sub-verbs are listed in cli/verbs.py; record, play, the player window, cut and merge are in
log_record.py, log_play.py, log_player.py and log_edit.py)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import (
    add_length_options,
    length_limit,
    log_warning,
    open_log,
    read_status,
    topic_arg,
)


def info_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log info",
        description="Summarise an event log: topics, types, counts, time span and rates. A "
        "finished file is summarised from its summary; each chunk's header is compared with it "
        "(a warning when they disagree). Exit status 1 when the file cannot be read or, with "
        "--check, when a chunk is damaged.",
    )
    p.add_argument("file", help="an MCAP file")
    p.add_argument(
        "--check",
        action="store_true",
        help="read every chunk (CRC, decompression, records) and count its events against the "
        "summary: each damaged chunk is an error line",
    )
    ns = p.parse_args(argv)
    from miro_gen.eventlog.check import damage, disagreements
    from miro_gen.eventlog.reader import LogError
    from miro_gen.eventlog.show import date_text

    log = open_log(ns.file)
    if log is None:
        return 1
    counts: dict[int, int] = {}
    first = last = None
    error = None
    problems: list[str] = []  # --check: damage found (errors)
    disagree: list[str] = []  # otherwise: the summary and the chunks' headers disagree
    checked = ""
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
            checked = "every chunk read (the file has no summary to compare)"
        topics = log.topics()
        if log.summary is not None:
            if ns.check:
                problems, chunks, events = damage(ns.file, log.summary)
                checked = f"{chunks} chunks, {events} events: readable, as the summary says"
            else:
                disagree = disagreements(ns.file, log.summary)
    total = sum(counts.values())
    duration = (last - first) / 1e9 if first is not None and last is not None else 0.0
    state = "finished"
    if log.unfinished or log.damaged_summary:
        state = "unfinished (no summary)" if log.unfinished else "summary damaged"
    elif problems:
        state = "damaged"
    elif disagree:
        state = "finished, but its summary and chunks disagree"
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
    if ns.check and error is None and not problems:
        print(f"checked:   {checked}")
    for line in _at_most(disagree, 10):
        print(f"{ns.file}: warning: summary and chunks disagree: {line}", file=sys.stderr)
    if disagree:
        print(f"{ns.file}: note: 'miro log info --check' reads every chunk", file=sys.stderr)
    if problems:
        for line in _at_most(problems, 20):
            print(f"{ns.file}: error: {line}", file=sys.stderr)
        return 1
    return read_status(ns.file, log, error)


def _at_most(lines: list[str], n: int) -> list[str]:
    """The first `n` lines, and one that counts the rest."""
    if len(lines) <= n:
        return lines
    return [*lines[:n], f"... and {len(lines) - n} more"]


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
    add_length_options(p)
    ns = p.parse_args(argv)
    limit = length_limit(p, ns)
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
                text = payload_text(topic.type_hash, message.data, limit)
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
