"""`miro bridge corba` and `miro bridge ros2`: relay events between a miro-gen event channel and
a CORBA event channel, or ROS 2 topics."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import COMMON, server_and_channel, split_common, topic_arg

_EPILOG = """\
examples:
  miro bridge corba --corba corbaname::robot:2809#EventChannel --to-corba '*/Odometry'
  miro bridge corba --corba IOR:... --from-corba Peer::Point=Point --from-corba '*'

A type bridged both ways would go round in circles: it is refused. See docs/CORBA.md.
"""


def _route(text: str) -> tuple[str, str]:
    name, _, event = text.partition("=")
    if not name:
        raise argparse.ArgumentTypeError(f"expected TYPE or TYPE=EVENT, not {text!r}")
    return name, event


def corba_main(argv: Sequence[str]) -> int:
    """`miro bridge corba`."""
    prog = "miro bridge"
    p = argparse.ArgumentParser(
        prog=f"{prog} corba",
        description="Relay events between a CORBA event channel (CosEventComm push model, "
        "as omniEvents serves it) and a miro-gen event channel. " + COMMON,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--corba",
        required=True,
        metavar="URL",
        help="the CORBA event channel: IOR:..., corbaloc:iiop:HOST:PORT/KEY or "
        "corbaname:iiop:HOST:PORT#NAME",
    )
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    p.add_argument(
        "--to-corba",
        action="append",
        default=[],
        type=topic_arg,
        metavar="DOMAIN/TYPE",
        help="push these miro-gen events into the CORBA channel (* for any part)",
    )
    p.add_argument(
        "--from-corba",
        action="append",
        default=[],
        type=_route,
        metavar="TYPE[=EVENT]",
        help="publish the CORBA channel's values of this IDL type (name, scoped name, "
        "repository id, or *) as events named EVENT (default: the type's name)",
    )
    ns = p.parse_args(split_common(p, argv))
    from miro_gen.bridges.corba import Bridge, Routes

    routes = Routes(ns.to_corba, dict(ns.from_corba))
    if not routes.to_corba and not routes.from_corba:
        p.error("nothing to bridge: give --to-corba and/or --from-corba")
    both = routes.overlap()
    if both:
        p.error(f"bridging {', '.join(sorted(both))} both ways would go round in circles")
    found = server_and_channel(p, prog, argv, ns.channel)
    if found is None:
        return 0
    server, channel = found
    try:
        bridge = Bridge(server, _corba_channel(server, ns.corba), channel, routes)
    except Exception as e:  # the CORBA side is unreachable or refuses: said in one line
        print(f"{prog}: {ns.corba}: {e}", file=sys.stderr)
        server.close()
        return 1
    server.on_shutdown(bridge.close)
    print(f"bridging {ns.corba} and {channel.name}", flush=True)
    server.run()
    return 0


def _corba_channel(server: Any, url: str) -> Any:
    """The CORBA channel of `url`, called through an IIOP invoker whose consumers are served
    on an address the channel's host can reach."""
    from miro_gen.corba.client import IIOPInvoker
    from miro_gen.corba.events import EventChannel
    from miro_gen.corba.ior import ior_from_ref
    from miro_gen.corba.naming import resolve_url
    from miro_gen.service.iiop import iiop_addresses, serve_iiop

    invoker = IIOPInvoker(server.invoker)
    ref = resolve_url(invoker, url)
    profile = ior_from_ref(ref).iiop_profile()
    towards = f"tcp://{profile.host}:{profile.port}" if profile else server.options.naming
    addresses = iiop_addresses(server.options, towards)
    invoker.server = serve_iiop(invoker, server.options, addresses.bind, addresses.advertise)
    server.on_shutdown(invoker.close)
    return EventChannel(ref, invoker)


_ROS2_EPILOG = """\
examples:
  miro bridge ros2 --to-ros2 'robot1/Odometry=/odom' --from-ros2 /cmd_vel:geometry_msgs/msg/Twist
  miro bridge ros2 --from-ros2 /scan:sensor_msgs/msg/LaserScan=Scan --channel robot1/EventChannel

The payloads are ROS 2 types miro-idl made of their .msg files (on PYTHONPATH). A topic bridged
both ways would go round in circles: it is refused. See docs/ROS2.md.
"""


def _to_ros2(text: str) -> tuple[tuple[str, str], str]:
    sub, eq, topic = text.partition("=")
    if not eq or not topic.startswith("/"):
        raise argparse.ArgumentTypeError(f"expected DOMAIN/TYPE=/TOPIC, not {text!r}")
    return topic_arg(sub), topic


def _from_ros2(text: str) -> tuple[str, tuple[str, str]]:
    head, _, event = text.partition("=")
    topic, colon, ros_type = head.partition(":")
    if not colon or not topic.startswith("/") or ros_type.count("/") != 2:
        raise argparse.ArgumentTypeError(f"expected /TOPIC:pkg/msg/Type[=EVENT], not {text!r}")
    return topic, (ros_type, event or ros_type.rsplit("/", 1)[1])


def ros2_main(argv: Sequence[str]) -> int:
    """`miro bridge ros2`."""
    prog = "miro bridge"
    p = argparse.ArgumentParser(
        prog=f"{prog} ros2",
        description="Relay events between a miro-gen event channel and ROS 2 topics (DDS, as "
        "ROS 2 Kilted's RMWs; the ros2 extra). " + COMMON,
        epilog=_ROS2_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    p.add_argument("--node", default="miro_bridge", metavar="NAME", help="the ROS 2 node's name")
    p.add_argument(
        "--to-ros2", action="append", default=[], type=_to_ros2, metavar="DOMAIN/TYPE=/TOPIC",
        help="publish these events (* for any part of DOMAIN/TYPE) on the ROS 2 topic",
    )  # fmt: skip
    p.add_argument(
        "--from-ros2", action="append", default=[], type=_from_ros2,
        metavar="/TOPIC:pkg/msg/Type[=EVENT]",
        help="push the topic's messages as events named EVENT (default: the type's name)",
    )  # fmt: skip
    ns = p.parse_args(split_common(p, argv))
    try:
        from miro_gen.bridges.ros2 import Bridge, RouteError, Routes
        from miro_gen.ros2.node import Node
    except ImportError as e:
        print(f"{prog}: ROS 2 needs the ros2 extra (pip install 'miro-gen[ros2]'): {e}",
              file=sys.stderr)  # fmt: skip
        return 1
    routes = Routes(dict(ns.to_ros2), dict(ns.from_ros2))
    if not routes.to_ros2 and not routes.from_ros2:
        p.error("nothing to bridge: give --to-ros2 and/or --from-ros2")
    both = routes.overlap()
    if both:
        p.error(f"bridging {', '.join(sorted(both))} both ways would go round in circles")
    found = server_and_channel(p, prog, argv, ns.channel)
    if found is None:
        return 0
    server, channel = found
    try:
        bridge = Bridge(server, channel, routes, Node(ns.node))
    except (RouteError, ValueError) as e:
        print(f"{prog}: {e}", file=sys.stderr)
        server.close()
        return 1
    server.on_shutdown(bridge.close)
    print(f"bridging {channel.name} and ROS 2 (node /{ns.node})", flush=True)
    server.run()
    return 0
