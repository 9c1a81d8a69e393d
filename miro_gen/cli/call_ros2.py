"""`miro call --ros2 SERVICE [TYPE] [REQUEST]`: call a ROS 2 service from the shell, as
`ros2 service call` does (miro_gen/ros2/services.py `Client`: DDS as the RMWs of ROS 2 Kilted,
calls answered by rclpy on Fast DDS, rmw_cyclonedds or another miro process; the `ros2` extra).

The service's type is the one its endpoints announce on the graph (or the one given), called
with the generated class of that type found on the module path (miro-idl of its `.srv` files).
The request is read as `miro pub --ros2` reads a message (YAML, `-`: the standard input); the
response is printed as `miro call` prints a result. One `--timeout` bounds it all: finding the
service, matching its server, and the reply.
"""

from __future__ import annotations

import argparse
import re
import time
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import add_length_options, length_limit
from miro_gen.cli.live_ros2 import TICK, error, node_name, ros_name, verb_parser
from miro_gen.cli.log_ros2 import ros2_missing, stopped_by_signals

TIMEOUT = 10.0  # seconds, by default, for the whole call (as `miro call`)
NO_SRV_TYPE = "(compile its .srv files with miro-idl and put them on PYTHONPATH)"
SRV_TYPE = re.compile(r"^[A-Za-z_]\w*/srv/[A-Za-z_]\w*$")


def parser() -> argparse.ArgumentParser:
    p = verb_parser(
        "call",
        "Call a ROS 2 service with REQUEST (YAML or JSON: '{data: true}'; - reads it from the "
        "standard input; default {}) and print its response, as ros2 service call does.",
    )
    p.add_argument("service", metavar="SERVICE", help="the ROS 2 service (/enable)")
    p.add_argument(
        "first",
        nargs="?",
        metavar="TYPE",
        help="its type (std_srvs/srv/SetBool; default: the one on the graph, or --type)",
    )
    p.add_argument("second", nargs="?", metavar="REQUEST", help="the request (default {})")
    p.add_argument("--type", metavar="TYPE", help="the service's type, as the TYPE word")
    p.add_argument(
        "--timeout",
        type=float,
        default=TIMEOUT,
        metavar="S",
        help=f"seconds to find the service, match it and have its reply (default {TIMEOUT:g})",
    )
    p.add_argument(
        "--json", action="store_true", help="print the response as JSON (sequences whole)"
    )
    add_length_options(p)
    return p


def _type_and_request(p: argparse.ArgumentParser, ns: argparse.Namespace) -> tuple[str | None, str]:
    """(the type given, or None; the request's text) from the words after SERVICE."""
    words = [w for w in (ns.first, ns.second) if w is not None]
    rtype = ns.type
    if words and (len(words) == 2 or SRV_TYPE.match(words[0])):
        if rtype is not None and rtype != words[0]:
            p.error(f"two types given: {words[0]} and --type {rtype}")
        rtype = words.pop(0)
    if rtype is not None and not SRV_TYPE.match(rtype):
        p.error(f"{rtype!r} is not a service type (pkg/srv/Name)")
    return rtype, words[0] if words else "{}"


def call_main(argv: Sequence[str]) -> int:
    prog = "miro call --ros2"
    p = parser()
    ns = p.parse_args(argv)
    if ns.timeout <= 0:
        p.error("--timeout must be more than 0 seconds")
    limit = length_limit(p, ns)
    service = ros_name(p, ns.service)
    given, text = _type_and_request(p, ns)
    if ros2_missing(prog):
        return 1
    from miro_gen.live.show import dump
    from miro_gen.live.values import to_plain
    from miro_gen.ros2.domain import Ros2DomainError
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.services import Client, ServiceTimeout

    deadline = time.monotonic() + ns.timeout
    try:
        # a type given: a bad type or request is said before any look at the graph
        found = None if given is None else _request(given, text)
        with stopped_by_signals() as stop, Node(node_name("call")) as node:
            if found is None:  # the type from the graph
                types = _wait_for_types(node, service, deadline, stop)
                if stop.is_set():
                    return 130
                if len(types) != 1:
                    return error(prog, _not_ready(service, None, types, ns.timeout))
                found = _request(types[0], text)
            cls, request = found
            client: Client[Any, Any] = Client(node, cls, service)
            if not client.wait_for_service(max(deadline - time.monotonic(), 0.0)):
                types = node.graph.services().get(service, [])
                return error(prog, _not_ready(service, given, types, ns.timeout))
            try:
                response = client.call(request, timeout=max(deadline - time.monotonic(), 0.01))
            except ServiceTimeout:
                return error(prog, f"no reply from {service} within {ns.timeout:g} s (--timeout)")
    except (Ros2DomainError, BadRequest) as e:
        return error(prog, str(e))
    print(dump(to_plain(response, None if ns.json else limit), ns.json))
    return 0


class BadRequest(ValueError):
    """A type not generated here, or a request that does not fit it (the message says which)."""


def _request(rtype: str, text: str) -> tuple[Any, Any]:
    """(the service class, the request read from `text`); BadRequest says why not."""
    from miro_gen.live.values import from_text
    from miro_gen.ros2.bag import message_class
    from miro_gen.ros2.types import service_parts

    cls = message_class(rtype)
    if cls is None:
        raise BadRequest(f"no generated type here for {rtype} {NO_SRV_TYPE}")
    try:
        request_cls, _ = service_parts(cls)
        return cls, from_text(request_cls, text)
    except (TypeError, ValueError) as e:
        raise BadRequest(f"{rtype}: {e}") from None


def _wait_for_types(node: Any, service: str, deadline: float, stop: Any) -> list[str]:
    """The service's types on the graph, once it has some (or [] at the deadline)."""
    while True:
        types: list[str] = node.graph.services().get(service, [])
        if types or time.monotonic() >= deadline or stop.wait(TICK):
            return types


def _not_ready(service: str, given: str | None, types: list[str], timeout: float) -> str:
    """Why no server of the service was found (`types`: its types on the graph)."""
    if len(types) > 1 and given is None:
        return f"{service} has more than one type ({', '.join(types)}): give one"
    if given is not None and types and given not in types:
        return f"{service} is {', '.join(types)} on the ROS 2 graph, not {given}"
    if not types:
        return f"no service {service} on the ROS 2 graph after {timeout:g} s (--timeout)"
    return f"no server of {service} matched within {timeout:g} s (--timeout)"
