"""The `miro` verbs, in one table: `miro --help`, the dispatcher (cli/main.py), the help of a
verb made of sub-verbs, and shell completion (cli/complete.py) all read `VERBS`.

A verb names the function that runs it as `"module:function"` (called with the words after the
verb, or after its sub-verb), imported only when it runs: `miro --help` and a Tab import no
verb's module. A sub-verb is one line in its verb's `subs`; one without a function of its own
is parsed by its verb's function (`miro param get|set|dump`, whose parser takes the sub-verbs'
help from here).
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable, Sequence
from typing import NamedTuple, cast

Run = Callable[[Sequence[str]], int]


class Verb(NamedTuple):
    """A verb (or a sub-verb) of `miro` (a named tuple: dataclasses would cost `miro`'s
    start-up the import of `inspect`)."""

    name: str
    help: str  # one line: `miro --help`, the verb's own list of sub-verbs
    run: str = ""  # "module:function", called with the words after it; "" for sub-verbs only
    subs: tuple[Verb, ...] = ()
    description: str = ""  # the help of a verb made of sub-verbs (default: `help`)
    parser: str = ""  # "module:function" giving its ArgumentParser: its options are completed
    complete: str = ""  # "module:function(words, args)": what its arguments may be (complete.py)
    common: bool = False  # takes the common options (--naming, -MNC, ...): completed too
    hidden: bool = False  # not listed (`_complete`, which the shell calls)

    def sub(self, name: str) -> Verb | None:
        return next((s for s in self.subs if s.name == name), None)


def _live(name: str, help: str, module: str, complete: str = "") -> Verb:
    """A live tool: `module:NAME_main`, its `parser()`, the common options."""
    return Verb(
        name,
        help,
        run=f"{module}:{name}_main",
        parser=f"{module}:parser",
        complete=f"miro_gen.cli.complete:{complete}" if complete else "",
        common=True,
    )


VERBS: tuple[Verb, ...] = (
    Verb("idl", "compile IDL files (same as miro-idl)", run="miro_gen.cli.idl:command"),
    Verb(
        "params",
        "compile parameter files (same as miro-params); `miro params show|validate FILE` checks "
        "run-time documents",
        run="miro_gen.cli.params:main",
        subs=(
            Verb(
                "show",
                "print the effective values: defaults merged with the document",
                run="miro_gen.cli.params_tools:show_main",
            ),
            Verb(
                "validate",
                "check documents; exit 1 listing every problem (for CI)",
                run="miro_gen.cli.params_tools:validate_main",
            ),
        ),
    ),
    Verb("naming", "run the naming service", run="miro_gen.cli.naming:naming_main"),
    Verb(
        "nslist",
        "print the names bound in the naming service",
        run="miro_gen.cli.naming:nslist_main",
        common=True,
    ),
    Verb(
        "nsunbind",
        "free names kept for a server of yours that stopped",
        run="miro_gen.cli.naming:nsunbind_main",
        common=True,
    ),
    Verb(
        "demo",
        "run the manual's examples A to D with a naming service",
        run="miro_gen.cli.demo:demo_main",
    ),
    Verb(
        "launch",
        "start a robot's services from a launch file (TOML)",
        run="miro_gen.cli.launch:launch_main",
        parser="miro_gen.cli.launch:parser",
    ),
    _live(
        "call",
        "call an operation of a running object (or a ROS 2 service: --ros2)",
        "miro_gen.cli.call",
        "call_args",
    ),
    _live(
        "pub",
        "publish an event (or a ROS 2 message: --ros2) by hand",
        "miro_gen.cli.pub",
        "pub_args",
    ),
    Verb(
        "list",
        "the running services, their objects, events and parameters (--ros2: the ROS 2 graph)",
        run="miro_gen.cli.listing:list_main",
        parser="miro_gen.cli.listing:parser",
        complete="miro_gen.cli.complete:list_args",
        common=True,
    ),
    Verb(
        "param",
        "get, set or dump the parameters of a running service",
        run="miro_gen.cli.param:param_main",
        parser="miro_gen.cli.param:parser",
        complete="miro_gen.cli.complete:param_args",
        common=True,
        subs=(  # parsed by param_main
            Verb("get", "print parameters: every set, a set, or one value"),
            Verb("set", "change one value, checked as a run-time document is"),
            Verb("dump", "every set, as a run-time document (-MCF reads it back)"),
        ),
    ),
    Verb(
        "build",
        "regenerate generated/ when IDL or parameter files changed",
        run="miro_gen.cli.build:build_main",
    ),
    Verb(
        "completion",
        'shell completion: eval "$(miro completion bash)"',
        run="miro_gen.cli.complete:completion_main",
    ),
    Verb(
        "_complete",
        "the candidates at a Tab (the shell calls it)",
        run="miro_gen.cli.complete:complete_main",
        hidden=True,
    ),
    Verb(
        "doctor",
        "which naming services are visible, and why one cannot be reached",
        run="miro_gen.cli.doctor:doctor_main",
        common=True,
    ),
    Verb(
        "sim",
        "simulate a device: nmea (a GPS receiver), scip (a laser scanner), camera, laser",
        description="Simulate a device, to run the drivers without hardware.",
        subs=(
            Verb(
                "nmea",
                "a GPS receiver (NMEA 0183) on a pseudo-terminal",
                run="miro_gen.cli.sim:nmea_main",
            ),
            Verb(
                "scip",
                "a Hokuyo laser scanner (SCIP 2.0) on a pseudo-terminal or a TCP port",
                run="miro_gen.cli.sim:scip_main",
            ),
            Verb(
                "camera",
                "a camera: a video file, or an MJPEG stream over HTTP",
                run="miro_gen.cli.sim:camera_main",
            ),
            Verb(
                "laser",
                "a laser scanner's scans as events on a channel (1,081 beams at 40 Hz)",
                run="miro_gen.cli.sim_laser:laser_main",
            ),
        ),
    ),
    Verb("new", "scaffold a service in one of Miro's patterns", run="miro_gen.cli.new:new_main"),
    Verb("run", "run a service of this project (services/NAME)", run="miro_gen.cli.run:run_main"),
    Verb(
        "log",
        "record, replay and inspect event logs (MCAP)",
        description="Record event channels into MCAP files, replay them, and look into them.",
        subs=(
            Verb(
                "record",
                "record events of a channel into an MCAP file (Miro's LogNotify)",
                run="miro_gen.cli.log_record:record_main",
            ),
            Verb(
                "play",
                "replay logs into each robot's channel with their original timing (LogPlayer)",
                run="miro_gen.cli.log_play:play_main",
            ),
            Verb(
                "player",
                "the player's window: play, seek, step, cut, plot (Miro's LogPlayer GUI)",
                run="miro_gen.cli.log_player:player_main",
            ),
            Verb(
                "info",
                "summarise a log: topics, types, counts, time span, rates",
                run="miro_gen.cli.log:info_main",
            ),
            Verb("echo", "print the events of a log, decoded", run="miro_gen.cli.log:echo_main"),
            Verb(
                "cut",
                "write part of a log to a new one, or repair a log (Miro's LogTruncate)",
                run="miro_gen.cli.log_edit:cut_main",
            ),
            Verb(
                "merge",
                "merge logs into one, in log-time order",
                run="miro_gen.cli.log_edit:merge_main",
            ),
        ),
    ),
    Verb(
        "echo",
        "print the events of a topic (or ROS 2 topic: --ros2) as they arrive",
        run="miro_gen.cli.live:echo_main",
        parser="miro_gen.cli.live:echo_parser",
        complete="miro_gen.cli.complete:topic_args",
        common=True,
    ),
    Verb(
        "hz",
        "print the rate of the events of a topic (or ROS 2 topic: --ros2)",
        run="miro_gen.cli.live:hz_main",
        parser="miro_gen.cli.live:hz_parser",
        complete="miro_gen.cli.complete:topic_args",
        common=True,
    ),
    Verb(
        "keys",
        "make the key of a robot or fleet (CURVE, and TLS for Zenoh)",
        description="Make the key that the processes of a robot (or of a fleet) share: with it "
        "(--keys FILE, or MIRO_KEYS), every connection is encrypted and only processes that "
        "hold it can call, publish or subscribe (ZeroMQ CURVE; on the Zenoh backbone, mutual "
        "TLS with the certificates made beside it).",
        subs=(
            Verb(
                "new",
                "write a new key pair: NAME.key_secret (secret: copy it to each machine that "
                "must take part, readable by its user only) and NAME.key (public), and the TLS "
                "files of the Zenoh backbone: a CA (NAME.ca.pem, NAME.ca_secret.pem) and "
                "NAME's certificate (NAME.cert.pem, NAME.cert_secret.pem)",
                run="miro_gen.cli.keys:new_main",
            ),
        ),
    ),
    Verb(
        "foxglove",
        "serve the running robot to Foxglove and Lichtblick (WebSocket)",
        run="miro_gen.cli.foxglove:foxglove_main",
        parser="miro_gen.cli.foxglove:parser",
        common=True,
    ),
    Verb(
        "bridge",
        "relay events with a CORBA event channel or ROS 2 topics (bridge corba, ros2)",
        description="Relay events between miro-gen's event channels and another middleware's.",
        subs=(
            Verb(
                "corba",
                "with a CORBA event channel (CosEventComm push model, as omniEvents serves it)",
                run="miro_gen.cli.bridge:corba_main",
            ),
            Verb(
                "ros2",
                "with ROS 2 topics (DDS, as ROS 2's RMWs; the ros2 extra)",
                run="miro_gen.cli.bridge:ros2_main",
            ),
        ),
    ),
)


def find(name: str, table: Sequence[Verb] = VERBS) -> Verb | None:
    return next((v for v in table if v.name == name), None)


def verb(path: str) -> Verb:
    """The verb or sub-verb `path` names (`"log"`, `"param get"`); KeyError when none."""
    found: Verb | None = None
    table: Sequence[Verb] = VERBS
    for name in path.split():
        found = find(name, table)
        if found is None:
            raise KeyError(path)
        table = found.subs
    if found is None:
        raise KeyError(path)
    return found


def target(spec: str) -> Callable[..., object]:
    """The function `"module:function"` names, its module imported now."""
    module, _, function = spec.partition(":")
    return cast("Callable[..., object]", getattr(importlib.import_module(module), function))


def run(v: Verb, args: Sequence[str], prog: str) -> int:
    """Run verb `v` (`prog` is how it was called: `miro log`) with the words after it."""
    if v.subs and args:
        sub = v.sub(args[0])
        if sub is not None and sub.run:
            return int(cast("Run", target(sub.run))(list(args[1:])))
    if v.run:
        return int(cast("Run", target(v.run))(list(args)))
    p = parser(v, prog)  # a verb made of sub-verbs, none (or an unknown one) given
    if not args:
        p.print_help()
        return 0
    p.parse_args(args)  # --help, or an error naming the sub-verbs
    return 2  # pragma: no cover - parse_args exits


def parser(v: Verb, prog: str) -> argparse.ArgumentParser:
    """The parser of a verb made of sub-verbs, for its help and its usage errors."""
    p = argparse.ArgumentParser(
        prog=prog,
        description=v.description or v.help,
        epilog=f"`{prog} COMMAND --help` gives the options of each.",
    )
    listed(p, v.subs)
    return p


def listed(p: argparse.ArgumentParser, table: Sequence[Verb]) -> None:
    """The verbs of `table` (but hidden ones) as sub-commands of `p`, for its help and its
    usage errors; each parses its own options when it runs."""
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for v in table:
        if not v.hidden:
            sub.add_parser(v.name, help=v.help, add_help=False)
