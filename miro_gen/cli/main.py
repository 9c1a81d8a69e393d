"""`miro`: the umbrella command. Sub-commands are added as the runtime grows."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from miro_gen.cli.common import VersionAction, piped

# The live tools: sub-command -> (module, function)
LIVE = {
    "call": ("miro_gen.cli.call", "call_main"),
    "pub": ("miro_gen.cli.pub", "pub_main"),
    "list": ("miro_gen.cli.listing", "list_main"),
    "param": ("miro_gen.cli.param", "param_main"),
    "build": ("miro_gen.cli.build", "build_main"),
    "completion": ("miro_gen.cli.complete", "completion_main"),
    "_complete": ("miro_gen.cli.complete", "complete_main"),
    "doctor": ("miro_gen.cli.doctor", "doctor_main"),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro",
        description="miro-gen: Miro (Middleware for Robots) in Python.",
        epilog="The IDL compiler is `miro-idl` (also `miro idl`), the parameter compiler "
        "`miro-params` (also `miro params`); see their --help.",
    )
    p.add_argument("--version", action=VersionAction)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.add_parser("idl", help="compile IDL files (same as miro-idl)", add_help=False)
    sub.add_parser(
        "params",
        help="compile parameter files (same as miro-params); `miro params show|validate FILE` "
        "checks run-time documents",
        add_help=False,
    )
    sub.add_parser("naming", help="run the naming service", add_help=False)
    sub.add_parser("nslist", help="print the names bound in the naming service", add_help=False)
    sub.add_parser(
        "nsunbind", help="free names kept for a server of yours that stopped", add_help=False
    )
    sub.add_parser(
        "demo", help="run the manual's examples A to D with a naming service", add_help=False
    )
    sub.add_parser(
        "launch", help="start a robot's services from a launch file (TOML)", add_help=False
    )
    sub.add_parser("call", help="call an operation of a running object", add_help=False)
    sub.add_parser("pub", help="publish an event by hand", add_help=False)
    sub.add_parser(
        "list", help="the running services, their objects, events and parameters", add_help=False
    )
    sub.add_parser(
        "param", help="get, set or dump the parameters of a running service", add_help=False
    )
    sub.add_parser(
        "build", help="regenerate generated/ when IDL or parameter files changed", add_help=False
    )
    sub.add_parser(
        "completion", help='shell completion: eval "$(miro completion bash)"', add_help=False
    )
    sub.add_parser(
        "doctor",
        help="which naming services are visible, and why one cannot be reached",
        add_help=False,
    )
    sub.add_parser(
        "sim",
        help="simulate a device: nmea (a GPS receiver), scip (a laser scanner), camera",
        add_help=False,
    )
    sub.add_parser("new", help="scaffold a service in one of Miro's patterns", add_help=False)
    sub.add_parser("run", help="run a service of this project (services/NAME)", add_help=False)
    sub.add_parser("log", help="record, replay and inspect event logs (MCAP)", add_help=False)
    sub.add_parser("echo", help="print the events of a topic as they arrive", add_help=False)
    sub.add_parser("hz", help="print the rate of the events of a topic", add_help=False)
    sub.add_parser("keys", help="make the key of a robot or fleet (CURVE)", add_help=False)
    sub.add_parser(
        "bridge", help="relay events with a CORBA event channel (bridge corba)", add_help=False
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run a sub-command; 130 after Ctrl-C (128 + the signal), without a traceback; quietly
    when the reader of its output goes away (`miro call ... | head`)."""
    try:
        return piped(dispatch, list(sys.argv[1:] if argv is None else argv))
    except KeyboardInterrupt:
        from miro_gen import lifecycle

        return lifecycle.exit_status()


def dispatch(args: list[str]) -> int:
    if args and args[0] == "idl":
        from miro_gen.cli import idl

        return idl.main(args[1:])
    if args and args[0] == "params":
        if len(args) > 1 and args[1] in ("show", "validate"):
            from miro_gen.cli import params_tools

            return params_tools.main(args[1:])
        from miro_gen.cli import params

        return params.main(args[1:])
    if args and args[0] in ("naming", "nslist", "nsunbind"):
        from miro_gen.cli import naming

        commands = {
            "naming": naming.naming_main,
            "nslist": naming.nslist_main,
            "nsunbind": naming.nsunbind_main,
        }
        return commands[args[0]](args[1:])
    if args and args[0] == "new":
        from miro_gen.cli import new

        return new.new_main(args[1:])
    if args and args[0] == "run":
        from miro_gen.cli import run

        return run.run_main(args[1:])
    if args and args[0] == "sim":
        from miro_gen.cli import sim

        return sim.sim_main(args[1:])
    if args and args[0] == "keys":
        from miro_gen.cli import keys

        return keys.keys_main(args[1:])
    if args and args[0] == "launch":
        from miro_gen.cli import launch

        return launch.launch_main(args[1:])
    if args and args[0] in LIVE:
        import importlib

        module, function = LIVE[args[0]]
        return int(getattr(importlib.import_module(module), function)(args[1:]))
    if args and args[0] == "demo":
        from miro_gen.cli import demo

        return demo.demo_main(args[1:])
    if args and args[0] == "log":
        from miro_gen.cli import log

        return log.main(args[1:])
    if args and args[0] in ("echo", "hz"):
        from miro_gen.cli import live

        return live.echo_main(args[1:]) if args[0] == "echo" else live.hz_main(args[1:])
    if args and args[0] == "bridge":
        from miro_gen.cli import bridge

        return bridge.bridge_main(args[1:])
    parser = build_parser()
    ns = parser.parse_args(args)
    if ns.command is None:
        parser.print_help()
        return 0
    return 0  # pragma: no cover - every sub-command returns above


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
