"""`miro list|echo|hz|pub --ros2`: the ROS 2 graph and its topics, as `ros2 node list`,
`ros2 topic list -t`, `ros2 topic echo`, `ros2 topic hz` and `ros2 topic pub` show and use
them (miro_gen/ros2: DDS as the RMWs of ROS 2 Kilted; the `ros2` extra).

A topic's type is the one its endpoints announce on the graph (or the one given), decoded with
the generated class of that type found on the module path (miro-idl of its `.msg` files). A
subscription takes the QoS that hears every publisher of the topic ("best available", as
`ros2 topic echo`); the tools' own nodes are hidden (their names start with `_`).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from miro_gen.cli.eventargs import add_length_options, length_limit
from miro_gen.cli.log_ros2 import ros2_missing, stopped_by_signals

TICK = 0.1  # seconds between looks at the graph while a topic is waited for
CHECK = 0.5  # seconds between looks for a publisher of another type than the one given
TOLD_AFTER = 2.0  # seconds of waiting before saying what is waited for
SPIN_TIME = 2.0  # seconds `miro list --ros2` watches discovery at least, by default
NODES_WAIT = 10.0  # seconds it waits more, at most, for the nodes of the participants found
ACK_WAIT = 5.0  # seconds `miro pub --ros2` lets its last message reach reliable subscribers
NO_TYPE = "(compile its .msg files with miro-idl and put them on PYTHONPATH)"


def wants_ros2(argv: Sequence[str]) -> bool:
    """Whether `--ros2` is among the options (before a `--`)."""
    for arg in argv:
        if arg == "--":
            return False
        if arg == "--ros2":
            return True
    return False


def add_ros2_flag(p: argparse.ArgumentParser, verb: str, what: str = "topics") -> None:
    p.add_argument(
        "--ros2",
        action="store_true",
        help=f"ROS 2 {what} over DDS instead (the ros2 extra): see miro {verb} --ros2 --help",
    )


def verb_parser(verb: str, description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=f"miro {verb} --ros2",
        description=description + " ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE apply; "
        "the types must be generated here (miro-idl on their .msg or .srv files, on PYTHONPATH).",
    )
    p.add_argument("--ros2", action="store_true", help="(the ROS 2 form of the command)")
    return p


def _qos_option(p: argparse.ArgumentParser, default: str) -> None:
    from miro_gen.ros2.qos import PROFILES

    p.add_argument(
        "--qos-profile",
        choices=sorted(PROFILES),
        help=f"the QoS profile (default: {default})",
    )


def node_name(verb: str) -> str:
    """A hidden node of this process (`ros2 node list` leaves it out), as ros2cli's."""
    return f"_miro_{verb}_{os.getpid()}"


def error(prog: str, text: str) -> int:
    print(f"{prog}: error: {text}", file=sys.stderr)
    return 1


# -- miro list --ros2 ------------------------------------------------------------------------


def list_parser() -> argparse.ArgumentParser:
    p = verb_parser(
        "list",
        "List the ROS 2 graph: its nodes, its topics with their types and how many publish "
        "and subscribe to each, and its services with their types (as ros2 node list, "
        "ros2 topic list -t, ros2 service list -t).",
    )
    p.add_argument(
        "pattern",
        nargs="?",
        default="*",
        metavar="PATTERN",
        help="only the nodes, topics and services whose name matches, as in the shell (/robot/*)",
    )
    p.add_argument("-a", "--all", action="store_true", help="hidden nodes and topics too (_name)")
    p.add_argument("--json", action="store_true", help="print it all as JSON")
    p.add_argument(
        "--spin-time",
        type=float,
        default=SPIN_TIME,
        metavar="S",
        help=f"how long to watch discovery before listing (default {SPIN_TIME:g} s); then "
        f"the nodes of the participants found are waited for ({NODES_WAIT:g} s at most)",
    )
    return p


def list_main(argv: Sequence[str]) -> int:
    prog = "miro list --ros2"
    p = list_parser()
    ns = p.parse_args(argv)
    if ns.spin_time < 0:
        p.error("--spin-time must be 0 or more")
    if ros2_missing(prog):
        return 1
    from miro_gen.ros2.domain import Ros2DomainError
    from miro_gen.ros2.node import Context

    try:
        with stopped_by_signals() as stop, Context() as context:
            graph = context.graph
            stop.wait(ns.spin_time)
            deadline = time.monotonic() + NODES_WAIT
            while graph.unannounced() and time.monotonic() < deadline and not stop.wait(TICK):
                pass
            nodes = [_joined(n) for n in graph.nodes()]
            endpoints = graph.endpoints()
            topics, services = graph.topics(), graph.services()
    except Ros2DomainError as e:
        return error(prog, str(e))

    def shown(name: str) -> bool:
        hidden = any(part.startswith("_") for part in name.split("/"))
        return (ns.all or not hidden) and _matches(name, ns.pattern)

    counts = _counts(endpoints)
    listing = {
        "nodes": [n for n in nodes if shown(n)],
        "topics": {
            t: {"types": types, "publishers": counts.get((t, False), 0),
                "subscribers": counts.get((t, True), 0)}
            for t, types in topics.items() if shown(t)
        },
        "services": {s: types for s, types in services.items() if shown(s)},
    }  # fmt: skip
    if ns.json:
        print(json.dumps(listing, indent=2))
        return 0
    _print_listing(listing)
    return 0


def _joined(node: tuple[str, str]) -> str:
    namespace, name = node
    return namespace.rstrip("/") + "/" + name


def _matches(name: str, pattern: str) -> bool:
    return fnmatch.fnmatchcase(name, pattern) or fnmatch.fnmatchcase(name.split("/")[-1], pattern)


def _counts(endpoints: list[Any]) -> dict[tuple[str, bool], int]:
    """(topic, is a reader) → how many endpoints."""
    from miro_gen.ros2 import names

    out: dict[tuple[str, bool], int] = {}
    for ep in endpoints:
        what = names.topic_from_dds(ep.dds_topic)
        if what is not None and what[0] == "topic":
            key = (what[1], ep.reader)
            out[key] = out.get(key, 0) + 1
    return out


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _print_listing(listing: dict[str, Any]) -> None:
    print("nodes:")
    for node in listing["nodes"]:
        print(f"  {node}")
    print("topics:")
    for topic, t in listing["topics"].items():
        counts = (
            f"{_plural(t['publishers'], 'publisher')}, {_plural(t['subscribers'], 'subscriber')}"
        )
        print(f"  {topic}  {', '.join(t['types'])}  ({counts})")
    print("services:")
    for service, types in listing["services"].items():
        print(f"  {service}  {', '.join(types)}")
    if not (listing["nodes"] or listing["topics"] or listing["services"]):
        print("(nothing found on the ROS 2 graph: is ROS_DOMAIN_ID the same?)")


# -- what echo and hz share ------------------------------------------------------------------


class Watched:
    """A topic a tool subscribes to once the graph (or the user) gives its type."""

    def __init__(self, topic: str, given_type: str | None) -> None:
        self.topic = topic
        self.given_type = given_type
        self.subscribed = False
        self.failed: str | None = None  # why it cannot be subscribed (said once)
        self.cls: Any = None  # the generated class of its type, once subscribed

    def try_subscribe(self, node: Any, profile: Any, handler: Callable[[bytes, Any], None]) -> bool:
        """Subscribe if the type is known now; False if it is still waited for."""
        from miro_gen.ros2 import names
        from miro_gen.ros2.bag import message_class
        from miro_gen.ros2.graph import best_available

        found = node.graph.topic_endpoints(self.topic)
        types = _types(found)
        rtype = self.given_type
        if rtype is None:
            if not types:
                return False
            if len(types) > 1:
                self.failed = f"{self.topic} has more than one type ({', '.join(types)}): give one"
                return False
            rtype = types[0]
        cls = message_class(rtype)
        if cls is None:
            self.failed = f"no generated type here for {rtype} {NO_TYPE}"
            return False
        if profile is None:
            profile = best_available([ep for ep in found if not ep.reader])
        node.reader(cls, names.topic_to_dds(self.topic), profile, cls._ros2_type_hash, handler)
        self.cls = cls
        self.subscribed = True
        return True

    def mismatch(self, node: Any) -> str | None:
        """Why the type given will hear none of the topic's publishers, if the graph says so."""
        own = node.context.participant.gid
        types = _types([e for e in node.graph.topic_endpoints(self.topic) if e.participant != own])
        if self.given_type is None or not types or self.given_type in types:
            return None
        return (
            f"{self.topic} is {', '.join(types)} on the ROS 2 graph, not {self.given_type}: "
            "its publishers will not match"
        )


def _types(endpoints: list[Any]) -> list[str]:
    from miro_gen.ros2 import names

    return sorted({names.type_from_dds(ep.dds_type) or ep.dds_type for ep in endpoints})


def ros_name(p: argparse.ArgumentParser, text: str) -> str:
    from miro_gen.ros2.names import Ros2NameError, expand_topic

    try:
        return expand_topic(text)
    except Ros2NameError as e:
        p.error(str(e))
    raise AssertionError  # pragma: no cover - p.error exits


def _profile(name: str | None) -> Any:
    from miro_gen.ros2.qos import PROFILES

    return None if name is None else PROFILES[name]


def _wait_told(prog: str, waiting: list[Watched], started: float, told: set[str]) -> None:
    """Say, once each, which topics are waited for (after a second) or cannot be taken."""
    for w in waiting:
        if w.failed and w.topic not in told:
            told.add(w.topic)
            print(f"{prog}: error: {w.failed}", file=sys.stderr, flush=True)
        elif time.monotonic() - started > TOLD_AFTER and w.topic + "?" not in told:
            told.add(w.topic + "?")
            print(f"{prog}: waiting for {w.topic} to appear on the ROS 2 graph", file=sys.stderr,
                  flush=True)  # fmt: skip


# -- miro echo --ros2 ------------------------------------------------------------------------


def echo_parser() -> argparse.ArgumentParser:
    p = verb_parser("echo", "Print the messages of a ROS 2 topic as they arrive, decoded.")
    p.add_argument("topic", metavar="TOPIC", help="the ROS 2 topic (/chatter)")
    p.add_argument(
        "type", nargs="?", metavar="TYPE", help="its type (default: the one on the graph)"
    )
    p.add_argument("-n", "--count", type=int, default=0, help="exit after N messages")
    add_length_options(p)
    _qos_option(p, "what hears every publisher: reliable unless one is best effort")
    return p


def echo_main(argv: Sequence[str]) -> int:
    prog = "miro echo --ros2"
    p = echo_parser()
    ns = p.parse_args(argv)
    limit = length_limit(p, ns)
    if ns.count < 0:
        p.error("--count must be 0 or more")
    topic = ros_name(p, ns.topic)
    if ros2_missing(prog):
        return 1
    from miro_gen.eventlog.show import clock_text, payload_text
    from miro_gen.ros2.domain import Ros2DomainError
    from miro_gen.ros2.node import Node

    watched = Watched(topic, ns.type)
    shown = [0]
    lock = threading.Lock()
    try:
        with stopped_by_signals() as stop, Node(node_name("echo")) as node:

            def show(data: bytes, info: Any) -> None:
                with lock:
                    if ns.count and shown[0] >= ns.count:
                        return
                    text = payload_text("", data, limit, watched.cls)
                    print(f"{clock_text(time.time_ns())} {topic} #{shown[0]} {text}", flush=True)
                    shown[0] += 1
                    if ns.count and shown[0] >= ns.count:
                        stop.set()

            started, told = time.monotonic(), set[str]()
            while not stop.is_set() and not watched.subscribed:
                if watched.try_subscribe(node, _profile(ns.qos_profile), show):
                    break
                _wait_told(prog, [watched], started, told)
                if watched.failed:
                    return 1
                stop.wait(TICK)
            while not stop.wait(CHECK):  # a type given that the graph contradicts: said once
                why = watched.mismatch(node)
                if why is not None:
                    print(f"{prog}: warning: {why}", file=sys.stderr, flush=True)
                    break
            stop.wait()
    except Ros2DomainError as e:
        return error(prog, str(e))
    return 0


# -- miro hz --ros2 --------------------------------------------------------------------------


def hz_parser() -> argparse.ArgumentParser:
    p = verb_parser(
        "hz",
        "Print, every second, the rate at which the messages of ROS 2 topics arrive, the min, "
        "max and standard deviation of the period, their lag (from the publisher's source "
        "timestamp to their arrival) and the bandwidth (CDR bytes a second).",
    )
    p.add_argument("topics", nargs="+", metavar="TOPIC", help="ROS 2 topics (/chatter)")
    p.add_argument("-w", "--window", type=int, default=100, help="periods averaged (default 100)")
    _qos_option(p, "what hears every publisher: reliable unless one is best effort")
    return p


def hz_main(argv: Sequence[str]) -> int:
    prog = "miro hz --ros2"
    p = hz_parser()
    ns = p.parse_args(argv)
    if ns.window < 1:
        p.error("--window must be 1 or more")
    topics = list(dict.fromkeys(ros_name(p, t) for t in ns.topics))
    if ros2_missing(prog):
        return 1
    from miro_gen.eventlog.rates import RateWindow
    from miro_gen.ros2.domain import Ros2DomainError
    from miro_gen.ros2.node import Node

    windows = {t: RateWindow(ns.window) for t in topics}
    lock = threading.Lock()

    def arrived(topic: str) -> Callable[[bytes, Any], None]:
        window = windows[topic]

        def on(data: bytes, info: Any) -> None:
            now = time.time_ns()
            sent = int(getattr(info, "source_timestamp", 0) or 0)
            lag = (now - sent) / 1e9 if 0 < sent <= now + 10**9 else None
            with lock:
                window.add(now / 1e9, len(data), lag)

        return on

    watched = [Watched(t, None) for t in topics]
    try:
        with stopped_by_signals() as stop, Node(node_name("hz")) as node:
            started, told = time.monotonic(), set[str]()
            next_report = time.monotonic() + 1.0
            while not stop.is_set():
                waiting = [w for w in watched if not w.subscribed and not w.failed]
                for w in waiting:
                    w.try_subscribe(node, _profile(ns.qos_profile), arrived(w.topic))
                _wait_told(prog, [w for w in watched if not w.subscribed], started, told)
                if all(w.failed for w in watched):
                    return 1
                if time.monotonic() >= next_report:
                    next_report += 1.0
                    with lock:
                        _report(windows, [w.topic for w in watched if w.subscribed])
                stop.wait(TICK)
    except Ros2DomainError as e:
        return error(prog, str(e))
    return 0


def _report(windows: dict[str, Any], topics: list[str]) -> None:
    from miro_gen.eventlog.rates import data_rate

    for topic in topics:
        window = windows[topic]
        stats = window.stats()
        if stats is None:
            print(f"{topic}: {'no messages yet' if not window.count else '1 message'}", flush=True)
            continue
        rate, low, high, std = stats
        lag_mean, lag_max = window.lag() or (0.0, 0.0)
        print(
            f"{topic}: {rate:.2f} Hz  min {low:.4f} s  max {high:.4f} s  std {std:.4f} s  "
            f"window {len(window.periods)}  lag {lag_mean * 1000:.1f} ms "
            f"(max {lag_max * 1000:.1f})  {data_rate(window.bandwidth() or 0.0)}",
            flush=True,
        )


# -- miro pub --ros2 -------------------------------------------------------------------------


def pub_parser() -> argparse.ArgumentParser:
    p = verb_parser(
        "pub",
        "Publish a message of TYPE with VALUE (YAML or JSON: '{data: hi}'; - reads it from "
        "the standard input; default {}) on a ROS 2 topic, once or RATE times a second.",
    )
    p.add_argument("topic", metavar="TOPIC", help="the ROS 2 topic (/chatter)")
    p.add_argument("type", metavar="TYPE", help="its ROS 2 type (std_msgs/msg/String)")
    p.add_argument("value", nargs="?", default="{}", metavar="VALUE", help="the message")
    p.add_argument("-r", "--rate", type=float, default=0, metavar="HZ", help="messages a second")
    p.add_argument(
        "-n", "--count", type=int, default=0,
        help="messages to publish (default: 1, or with --rate until Ctrl-C)",
    )  # fmt: skip
    p.add_argument(
        "-w", "--wait-matching-subscriptions", "--wait-matching", dest="wait_matching",
        type=int, metavar="N",
        help="before the first message, wait until N subscriptions match (default: 1 when the "
        "messages are counted, 0 with --rate until Ctrl-C)",
    )  # fmt: skip
    p.add_argument(
        "--max-wait", type=float, default=10.0, metavar="S",
        help="wait that long at most, then publish anyway (default 10 s; 0: no limit)",
    )  # fmt: skip
    _qos_option(p, "default: keep last 10, reliable, volatile")
    return p


def pub_main(argv: Sequence[str]) -> int:
    prog = "miro pub --ros2"
    p = pub_parser()
    ns = p.parse_args(argv)
    if ns.rate < 0 or ns.count < 0 or ns.max_wait < 0 or (ns.wait_matching or 0) < 0:
        p.error("--rate, --count, --wait-matching and --max-wait must be 0 or more")
    topic = ros_name(p, ns.topic)
    if ros2_missing(prog):
        return 1
    from miro_gen.live.values import from_text
    from miro_gen.ros2.bag import message_class
    from miro_gen.ros2.domain import Ros2DomainError
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.qos import DEFAULT

    cls = message_class(ns.type)
    if cls is None:
        return error(prog, f"no generated type here for {ns.type} {NO_TYPE}")
    try:
        message = from_text(cls, ns.value)
    except ValueError as e:
        return error(prog, str(e))
    count = ns.count or (0 if ns.rate else 1)
    wanted = ns.wait_matching if ns.wait_matching is not None else (1 if count else 0)
    try:
        with stopped_by_signals() as stop, Node(node_name("pub")) as node:
            publisher = node.publisher(cls, topic, _profile(ns.qos_profile) or DEFAULT)
            if not _wait_matching(prog, publisher, topic, wanted, ns.max_wait, stop):
                return 0
            sent = matched = 0
            period = 1.0 / ns.rate if ns.rate else 0.0
            due = time.monotonic()
            while not stop.is_set():
                matched = max(matched, publisher.subscribers())
                publisher.publish(message)
                print(f"published {topic} #{sent}", flush=True)
                sent += 1
                if count and sent >= count:
                    break
                due += period
                stop.wait(max(due - time.monotonic(), 0.0))
            publisher.wait_for_acks(ACK_WAIT)  # the last reaches reliable subscriptions
    except Ros2DomainError as e:
        return error(prog, str(e))
    return 1 if count == 1 and not matched else 0  # as miro pub: a lone message nobody took


def _wait_matching(
    prog: str, publisher: Any, topic: str, wanted: int, limit: float, stop: threading.Event
) -> bool:
    """Wait for `wanted` subscriptions to match (at most `limit` s, 0: no limit); False when
    stopped meanwhile."""
    started = time.monotonic()
    told = False
    many = _plural(wanted, "subscription")
    while publisher.subscribers() < wanted:
        waited = time.monotonic() - started
        if limit and waited >= limit:
            print(f"{prog}: {publisher.subscribers()} of {many} to {topic} after {limit:g} s "
                  "(--max-wait): publishing anyway", file=sys.stderr, flush=True)  # fmt: skip
            break
        if not told and waited >= 0.5:
            told = True
            print(f"{prog}: waiting for {many} to {topic}", file=sys.stderr, flush=True)
        if stop.wait(0.02):
            return False
    return True
