"""`miro demo`: the manual's examples A to D together, on one machine, with nothing to set up.

It is `services/demo.toml` run by `miro launch`'s supervisor: a naming service, then ExampleA
(server), ExampleB (its client), ExampleC (event supplier) and ExampleD (event consumer), each a
process of its own as on a robot, each started once what it needs is bound, and restarted if it
fails. Their output is interleaved line by line, each line labelled with the example it comes
from. Ctrl-C (or the end of `--duration`) stops them, consumers and clients first, then the
naming service. The naming service listens where `miro nslist` and `miro echo` look by default
when it can (tcp://127.0.0.1:2809, or $MIRO_NAMING), and the demo prints the commands that see
it from another terminal.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sys
import threading
from collections.abc import Sequence
from typing import IO

from miro_gen import resources
from miro_gen.launch.console import Console
from miro_gen.service.options import DEFAULT_NAMING, UsageError, naming_endpoint

NAMING_READY = "naming service at"


class DemoConsole(Console):
    """The launch's console, quiet about routine, that says after the naming service's first
    line how to see the demo from another terminal."""

    def __init__(self, stream: IO[str], labels: list[str], colour: bool) -> None:
        super().__init__(stream, labels, colour, routine=False)

    def line(self, label: str, text: str) -> None:
        super().line(label, text)
        if label == "naming" and text.startswith(NAMING_READY):
            super().line("naming", commands(text.split()[-1]))


def naming_address(given: str | None) -> str:
    """Where the demo's naming service listens: `given` (--naming, else $MIRO_NAMING), else
    the default address when nothing listens there, else a free port of loopback."""
    if given:
        return naming_endpoint(given)
    host, port = DEFAULT_NAMING.removeprefix("tcp://").rsplit(":", 1)
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, int(port)))
        except OSError:  # in use (another naming service, say)
            return "tcp://127.0.0.1:*"
    return DEFAULT_NAMING


def commands(endpoint: str) -> str:
    """The commands that see the demo from another terminal."""
    naming = "" if endpoint == DEFAULT_NAMING else f" --naming {endpoint}"
    return (
        f"see it from another terminal: miro nslist{naming}; "
        f"miro echo '*/ExampleEvent' --channel ExampleEventChannel{naming}"
    )


def demo_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro demo",
        description="Run the manual's examples A to D with a naming service (services/demo.toml, "
        "as miro launch runs it) and show their output, labelled. Stops on Ctrl-C or after "
        "--duration.",
    )
    p.add_argument(
        "--duration", type=float, default=0, help="seconds to run (default: until Ctrl-C)"
    )
    p.add_argument(
        "--period", type=float, default=1.0, help="seconds between ExampleC's events (default 1)"
    )
    p.add_argument(
        "--colour",
        choices=("auto", "always", "never"),
        default="auto",
        help="label colours (default: when the output is a terminal)",
    )
    p.add_argument("-MLL", "--log-level", type=int, default=4, help="Miro log level (default 4)")
    p.add_argument(
        "--naming",
        metavar="URL",
        default=os.environ.get("MIRO_NAMING"),
        help=f"where its naming service listens (default $MIRO_NAMING, else {DEFAULT_NAMING} "
        "when free, else a free port)",
    )
    ns = p.parse_args(argv)
    if ns.duration < 0 or ns.period <= 0:
        p.error("--duration must be at least 0 and --period more than 0")
    try:
        address = naming_address(ns.naming)
    except UsageError as e:
        p.error(str(e))
    folder = resources.services_dir()
    if folder is None or not (folder / "demo.toml").is_file():
        print(
            "miro demo: the examples (miro_gen/services/demo.toml, exampleA.py ...) are missing "
            "from this installation of miro-gen; reinstall it, or run it from a checkout",
            file=sys.stderr,
        )
        return 1
    from miro_gen.launch.spec import LaunchError, read_launch_file
    from miro_gen.launch.supervisor import Supervisor, plan

    try:
        spec = read_launch_file(folder / "demo.toml")
    except LaunchError as e:  # a broken installation
        print(f"miro demo: {e}", file=sys.stderr)
        return 1
    assert spec.naming is not None
    spec.naming.endpoint = address
    part = plan(spec)
    for service in part.services:
        if service.name == "exampleC":
            service.argv[-1] = f"{ns.period:g}"  # its one argument: seconds between events
        if service.python:  # the naming service on the command line too, where ps shows it
            service.argv += ["--naming", part.naming_url or address, "-MLL", str(ns.log_level)]
    colour = ns.colour == "always" or (ns.colour == "auto" and sys.stdout.isatty())
    console = DemoConsole(sys.stdout, [s.name for s in part.services], colour)
    supervisor = Supervisor(spec, part, console)
    interrupted: list[int] = []  # (no Event: a handler must not take locks, see stop_from_signal)

    def on_signal(signum: int, _frame: object) -> None:
        interrupted.append(signum)
        supervisor.stop_from_signal()

    old = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    if ns.duration:  # counted from when every example is up, as a user watching would

        def stop_later() -> None:
            while not supervisor.all_came_up and not supervisor.stopping.wait(0.05):
                pass
            if not supervisor.stopping.wait(ns.duration):
                supervisor.stop()

        threading.Thread(target=stop_later, name="demo-duration", daemon=True).start()
    try:
        status = supervisor.run()
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    console.line("naming", "stopped")
    if status == 0 and interrupted and not supervisor.all_came_up:
        return 128 + signal.SIGINT  # Ctrl-C before every example was up
    return status
