"""`miro launch robot.toml`: start a robot's services from a launch file, keep them up, stop
them all with one Ctrl-C. See miro_gen.launch.spec for the file and docs/LAUNCH.md."""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

from miro_gen.launch.console import Console, Row, format_table
from miro_gen.launch.spec import LaunchError, LaunchSpec, read_launch_file
from miro_gen.launch.supervisor import PlanError, Supervisor, plan


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro launch",
        description="Start the services of a launch file (TOML) in the order it declares, show "
        "their output labelled and a status table, restart them as their policies say, and "
        "stop them all on Ctrl-C (SIGTERM, then SIGKILL after the grace period). Exits 1 when "
        "a required service cannot stay up.",
    )
    p.add_argument("file", metavar="FILE", help="the launch file (robot.toml)")
    p.add_argument(
        "--host",
        metavar="NAME",
        help="start this host's part of the file (default: this machine's, when the file names "
        "it among its [hosts]; else every service)",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="check the file and print what would start, in order; start nothing",
    )
    p.add_argument(
        "--colour",
        "--color",
        choices=("auto", "always", "never"),
        help="colour the labels (default: the file's, else when the output is a terminal)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=0,
        metavar="S",
        help="stop everything after S seconds (default: run until Ctrl-C)",
    )
    p.add_argument(
        "--no-build",
        action="store_true",
        help="start even when the project's generated code is older than its IDL or parameter "
        "files (by default it is regenerated first, as miro build does)",
    )
    p.add_argument(
        "--no-status", action="store_true", help="no live status table, even on a terminal"
    )
    return p


def launch_main(argv: Sequence[str]) -> int:
    p = parser()
    ns = p.parse_args(argv)
    if not (math.isfinite(ns.duration) and ns.duration >= 0):
        p.error(f"--duration must be 0 or more seconds, not {ns.duration}")
    try:
        spec = read_launch_file(ns.file)
        part = plan(spec, ns.host)
    except LaunchError as e:
        for d in e.diagnostics:
            print(d, file=sys.stderr)
        return 1
    except PlanError as e:
        print(f"{ns.file}: error: {e}", file=sys.stderr)
        return 2
    if ns.check:
        print(describe(spec, part))
        return 0
    from miro_gen.cli.freshness import before_running

    if not ns.no_build and not before_running(spec.folder, "miro launch"):
        return 2
    if not part.services:
        print(f"{ns.file}: host {part.host} has no services to start", file=sys.stderr)
        return 0
    tty = sys.stdout.isatty()
    choice = ns.colour or spec.colour
    colour = choice == "always" or (choice == "auto" and tty)
    console = Console(
        sys.stdout, [s.name for s in part.services], colour, table=tty and not ns.no_status
    )
    supervisor = Supervisor(spec, part, console)
    old = {
        s: signal.signal(s, lambda *_: supervisor.stop_from_signal())
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    }
    if ns.duration > 0:
        timer = threading.Timer(ns.duration, supervisor.stop)
        timer.daemon = True
        timer.start()
    try:
        return supervisor.run()
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def describe(spec: LaunchSpec, part: object) -> str:
    """What `--check` prints: each service to start here, its command (placeholders filled in
    as they will be) and what it waits for."""
    from miro_gen.launch.supervisor import Part, fill, placeholders

    assert isinstance(part, Part)
    naming = part.naming_url or os.environ.get("MIRO_NAMING", "")
    rows: list[Row] = [("SERVICE", "AFTER", "RESTART", "COMMAND")]
    for s in part.services:
        params = f"<{s.name}.xml, written at start>" if s.params_file or s.parameters else ""
        values = placeholders(spec, s, naming, params)
        command = " ".join(_short(fill(a, values)) for a in s.argv)
        policy = s.restart.when
        if s.restart.when != "never" and s.restart.limit is not None:
            policy += f" (at most {s.restart.limit})"
        rows.append((s.name, ", ".join(s.after) or "-", policy, command))
    head = f"{spec.path}: {len(part.services)} to start"
    if part.host is not None:
        head += f" on {part.host}"
    if part.naming_url:
        head += f"; naming service at {part.naming_url}"
    if part.others:
        head += f"; elsewhere: {', '.join(sorted(part.others))}"
    return head + "\n" + format_table(rows)


def _short(word: str) -> str:
    if word == sys.executable:
        return "python"
    path = Path(word)
    if path.is_absolute():
        try:
            return str(path.relative_to(Path.cwd()))
        except ValueError:
            return word
    return word
