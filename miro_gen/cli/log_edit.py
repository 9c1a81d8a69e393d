"""`miro log cut` (Miro's LogTruncate) and `miro log merge`: new logs from parts of others.

Both copy events as they are, in log-time order, into a finished, indexed file: cut keeps a
span and some topics of one log, merge puts several logs into one. A log without its summary
(a recorder killed) or cut off in the middle is read up to its last sound record and written
whole, with its index: that is the repair LogTruncate did for Miro's logs.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.log_play import (
    add_selection_options,
    apply_selection,
    check_selection,
    open_files,
)


def cut_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log cut",
        description="Write part of a log to a new one: the events from --start to --end "
        "(seconds from its first event, both included), of --topics, less --exclude. A log "
        "without its index (its recorder was killed) or cut off in the middle is written up "
        "to its last sound record, with an index (Miro's LogTruncate).",
    )
    p.add_argument("input", metavar="IN", help="an MCAP log")
    p.add_argument("output", metavar="OUT", help="the new log")
    p.add_argument("-f", "--force", action="store_true", help="overwrite OUT if it exists")
    add_selection_options(p)
    ns = p.parse_args(argv)
    check_selection(p, ns)
    return _write(p, [ns.input], ns.output, ns)


def merge_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro log merge",
        description="Merge logs into one, in log-time order (several robots' recordings, or "
        "one recording in several files); channels of the same topic and type become one.",
    )
    p.add_argument("inputs", nargs="+", metavar="IN", help="MCAP logs")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="the new log")
    p.add_argument("-f", "--force", action="store_true", help="overwrite OUT if it exists")
    add_selection_options(p)
    ns = p.parse_args(argv)
    check_selection(p, ns)
    return _write(p, ns.inputs, ns.output, ns)


def _write(p: argparse.ArgumentParser, inputs: list[str], output: str, ns: Any) -> int:
    from miro_gen.eventlog.edit import write_selection
    from miro_gen.eventlog.fileset import FileSet
    from miro_gen.eventlog.progress import StatusLine
    from miro_gen.eventlog.reader import LogError

    if os.path.exists(output) and not ns.force:
        p.error(f"{output} exists (use --force to overwrite it)")
    real = os.path.realpath(output)
    if any(os.path.realpath(i) == real for i in inputs):
        p.error(f"{output} is one of the inputs: write to another file")
    files = FileSet()
    try:
        if not open_files(inputs, files, strict=False):
            return 1
        for line in apply_selection(files, ns):
            print(f"{p.prog}: {line}", file=sys.stderr)
        start, end = files.cut
        status = StatusLine()
        total = max(1, files.count)

        def progress(written: int) -> bool:
            status.update(f"{output}: {written} events ({100 * written / total:.0f} %)")
            return True

        try:
            written = write_selection(
                files, output, start, end, lambda n: n not in files.excluded, progress
            )
        except LogError as e:
            where = getattr(e, "path", output)
            status.done(f"{where}: error: {e}")
            return 1
        first, _ = files.span()
        span = f"{(start - first) / 1e9:.3f} to {(end - first) / 1e9:.3f} s" if files.count else ""
        status.done(f"{output}: {written} events {span}".rstrip())
        return 0
    finally:
        files.close()
