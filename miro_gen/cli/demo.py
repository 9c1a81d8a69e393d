"""`miro demo`: the manual's examples A to D together, on one machine, with nothing to set up.

An embedded naming service runs in this process; ExampleA (server), ExampleB (its client),
ExampleC (event supplier) and ExampleD (event consumer) run as processes of their own, as they
would on a robot, and their output is interleaved here line by line, each line labelled with the
example it comes from. Ctrl-C (or the end of `--duration`) stops them, consumers and clients
first, then the naming service. The naming service listens where `miro nslist` and `miro echo`
look by default when it can (tcp://127.0.0.1:2809, or $MIRO_NAMING), and the demo prints the
commands that see it from another terminal.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import zmq

from miro_gen import log
from miro_gen.cli.run import services_dir
from miro_gen.transport.invoker import ZmqInvoker
from miro_gen.transport.naming import NamingService
from miro_gen.transport.options import DEFAULT_NAMING, UsageError, naming_endpoint
from miro_gen.transport.reactor import Reactor

READY_TIMEOUT = 30.0  # seconds an example may take to start
STOP_TIMEOUT = 10.0  # seconds an example may take to stop after SIGINT
COLOURS = {"naming": 37, "exampleA": 36, "exampleB": 32, "exampleC": 35, "exampleD": 33}


class Output:
    """Prints labelled lines from several threads without mixing them."""

    def __init__(self, stream: IO[str], colour: bool) -> None:
        self.stream = stream
        self.colour = colour
        self.lock = threading.Lock()
        self.width = max(len(k) for k in COLOURS)

    def line(self, label: str, text: str) -> None:
        tag = f"{label:<{self.width}} |"
        if self.colour:
            tag = f"\033[{COLOURS.get(label, 37)}m{tag}\033[0m"
        with self.lock:
            self.stream.write(f"{tag} {text}\n")
            self.stream.flush()


@dataclass
class Example:
    """One example's process and the thread that copies its output."""

    label: str
    proc: subprocess.Popen[str]
    reader: threading.Thread
    ready: threading.Event


def start_example(
    label: str, script: Path, args: list[str], env: dict[str, str], out: Output, ready_text: str
) -> Example:
    """Start `script` and copy its output (stdout and stderr) to `out`, labelled."""
    proc = subprocess.Popen(
        [sys.executable, "-u", str(script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        text=True,
        env=env,
        start_new_session=True,  # Ctrl-C reaches miro demo only; it stops the examples in order
    )
    ready = threading.Event()

    def copy() -> None:
        assert proc.stdout is not None
        for text in proc.stdout:
            out.line(label, text.rstrip("\n"))
            if ready_text in text:
                ready.set()
        ready.set()  # it ended: nobody should wait for it any longer

    reader = threading.Thread(target=copy, name=f"demo-{label}", daemon=True)
    reader.start()
    return Example(label, proc, reader, ready)


def stop_example(example: Example, out: Output) -> int:
    """Interrupt an example as Ctrl-C would, wait for it; its exit status (0 for a clean
    stop)."""
    proc = example.proc
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            out.line(example.label, f"did not stop within {STOP_TIMEOUT:g} s: killed")
            proc.kill()
            proc.wait()
    example.reader.join(STOP_TIMEOUT)
    code = proc.returncode
    return 0 if code in (0, -signal.SIGINT, 128 + signal.SIGINT) else code


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
        description="Run the manual's examples A to D with an embedded naming service and "
        "show their output, labelled. Stops on Ctrl-C or after --duration.",
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
    folder = services_dir()
    if folder is None:
        print(
            "miro demo: the examples (miro_gen/services/exampleA.py ...) are missing from "
            "this installation of miro-gen; reinstall it, or run it from a checkout",
            file=sys.stderr,
        )
        return 1
    colour = ns.colour == "always" or (ns.colour == "auto" and sys.stdout.isatty())
    out = Output(sys.stdout, colour)
    log.configure(ns.log_level)

    stop = threading.Event()
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    reactor = Reactor(zmq.Context.instance())
    try:
        naming = NamingService(reactor, ZmqInvoker(reactor.context), address)
    except zmq.ZMQError as e:
        print(f"miro demo: cannot serve the naming service on {address}: {e}", file=sys.stderr)
        for s, handler in old.items():
            signal.signal(s, handler)
        return 1
    reactor_thread = reactor.run_in_thread()
    out.line("naming", f"naming service at {naming.endpoint}")
    out.line("naming", commands(naming.endpoint))

    env = dict(os.environ)
    root = folder.parent
    if (root / "generated").is_dir():  # a checkout: its generated code and miro_gen first
        env["PYTHONPATH"] = os.pathsep.join(
            [str(root / "generated"), str(root), *filter(None, [env.get("PYTHONPATH")])]
        )
    common = ["--naming", naming.endpoint, "-MLL", str(ns.log_level)]
    plan = [  # label, arguments, the line that says it is ready
        ("exampleA", [*common], "ExampleA is ready"),
        ("exampleB", [*common, "--period", "1"], "has been found"),
        ("exampleC", [*common, f"{ns.period:g}"], "publishes"),
        ("exampleD", [*common], "listens"),
    ]
    examples: list[Example] = []
    interrupted = False  # by Ctrl-C before every example was up
    try:
        for label, args, ready_text in plan:
            if stop.is_set():
                break
            example = start_example(label, folder / f"{label}.py", args, env, out, ready_text)
            examples.append(example)
            end = time.monotonic() + READY_TIMEOUT
            while not example.ready.wait(0.1) and not stop.is_set() and time.monotonic() < end:
                pass
            if example.proc.poll() not in (None, 0):
                out.line(label, f"exited with status {example.proc.returncode}")
                stop.set()  # the others depend on it: stop them too
                break
        interrupted = stop.is_set()  # a failure to start sets it too, and is reported below
        end = time.monotonic() + ns.duration if ns.duration else float("inf")
        while not stop.wait(0.1) and time.monotonic() < end:
            if all(e.proc.poll() is not None for e in examples):
                break
    finally:
        failed = [e.label for e in reversed(examples) if stop_example(e, out)]
        reactor.stop()
        reactor_thread.join(STOP_TIMEOUT)
        naming.close()  # after the reactor thread: its sockets are that thread's
        reactor.close()
        for s, handler in old.items():
            signal.signal(s, handler)
    if failed:
        print(f"miro demo: {', '.join(failed)} failed", file=sys.stderr)
        return 1
    out.line("naming", "stopped")
    return 128 + signal.SIGINT if interrupted else 0
