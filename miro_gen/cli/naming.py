"""`miro naming` (the naming service) and `miro nslist` (what it holds, as a tree)."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence

import zmq

from miro_gen import log
from miro_gen.exceptions import SystemException
from miro_gen.transport.invoker import ZmqInvoker
from miro_gen.transport.naming import NamingService
from miro_gen.transport.options import DEFAULT_NAMING, UsageError, naming_endpoint
from miro_gen.transport.reactor import Reactor


def naming_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro naming",
        description="Run the naming service: servers bind their objects' names in it, "
        "clients resolve them. Names of servers that stop renewing their leases expire.",
    )
    p.add_argument(
        "--endpoint",
        default=DEFAULT_NAMING,
        help=f"where to serve (default {DEFAULT_NAMING}, this machine only; for other hosts "
        "use this machine's address, or tcp://0.0.0.0:2809 for every interface)",
    )
    p.add_argument("-MLL", "--log-level", type=int, default=5, help="Miro log level (default 5)")
    ns = p.parse_args(argv)
    try:
        endpoint = naming_endpoint(ns.endpoint)
    except UsageError as e:
        p.error(str(e))
    log.configure(ns.log_level)
    reactor = Reactor(zmq.Context.instance())
    invoker = ZmqInvoker(reactor.context)
    try:
        service = NamingService(reactor, invoker, endpoint)
    except zmq.ZMQError as e:
        print(f"miro naming: cannot serve on {endpoint}: {e}", file=sys.stderr)
        return 1
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: reactor.stop())
    bound = service.adapter.socket.getsockopt_string(zmq.LAST_ENDPOINT)
    every = "://0.0.0.0:" in bound
    note = " (every interface: other hosts use this machine's address)" if every else ""
    print(f"naming service at {bound}{note}", flush=True)
    reactor.run()
    service.close()
    reactor.close()
    return 0


def nslist_main(argv: Sequence[str]) -> int:
    from miro_gen.transport.server import Client

    p = argparse.ArgumentParser(
        prog="miro nslist",
        description="Print the names bound in the naming service, as a tree (the manual's "
        "nslist). Accepts the common options: --naming, -ORBInitRef NameService=...",
    )
    p.add_argument("prefix", nargs="?", default="", help="only names under this path")
    try:
        client = Client(["miro nslist", *argv])
    except UsageError as e:
        p.error(str(e))
    ns = p.parse_args(client.argv[1:])
    try:
        entries = client.naming.registry._list(ns.prefix)
    except SystemException as e:
        print(f"miro nslist: {client.options.naming}: {e}", file=sys.stderr)
        return 1
    finally:
        client.close()
    shown: set[tuple[str, ...]] = set()
    for entry in entries:
        parts = entry.name.split("/")
        for depth in range(len(parts) - 1):
            if tuple(parts[: depth + 1]) not in shown:
                shown.add(tuple(parts[: depth + 1]))
                print("  " * depth + parts[depth] + "/")
        print("  " * (len(parts) - 1) + f"{parts[-1]}  ({entry.repo_id} at {entry.endpoint})")
    if not entries:
        print("(no names bound)")
    return 0
