"""`miro echo TOPIC` and `miro hz TOPIC`: look at the events on a channel as they arrive. The
channels are those the running suppliers of TOPIC publish on (their service objects say), as
`miro pub` finds them; `miro echo` decodes with the generated types here, else with the data
schemas those suppliers give."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import (
    COMMON,
    add_length_options,
    length_limit,
    resolve_or_wait,
    server_and_channel,
    split_common,
    topic_arg,
)
from miro_gen.cli.live_ros2 import add_ros2_flag, wants_ros2

MAX_TOPICS = 1000  # topics `miro hz` keeps statistics of
DEFAULT_CHANNEL = "EventChannel"


def _parser(prog: str, description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=description + " " + COMMON)
    p.add_argument(
        "topics",
        nargs="+",
        type=topic_arg,
        metavar="TOPIC",
        help="DOMAIN/TYPE, * for any part (robot1/Odometry, */Odometry, robot1/*)",
    )
    p.add_argument(
        "--channel",
        metavar="NAME",
        help="the event channel (default: the ones the suppliers of TOPIC publish on, else "
        f"{DEFAULT_CHANNEL})",
    )
    add_ros2_flag(p, prog.split()[-1])
    return p


def _tap(server: Any, channel: Any, topics: list[tuple[str, str]], handler: Any) -> Any:
    from miro_gen.eventlog.tap import RawEventTap
    from miro_gen.runtime import registry

    registry.discover()
    return RawEventTap(channel, topics, handler)


class Suppliers:
    """The running suppliers of `topics`, as their service objects describe them: the channel
    they publish on, and the types of their payloads, compiled from the data schemas they give
    where no generated type here has them. Nothing is found (and nothing said) without a
    naming service to ask."""

    def __init__(self, prog: str, argv: Sequence[str], topics: list[tuple[str, str]]) -> None:
        from miro_gen.live.remote import LiveError, Robot

        self.prog = prog
        self.topics = topics
        self.tried: set[str] = set()  # type hashes looked for
        try:
            self.robot: Robot | None = Robot([prog, *argv])
        except LiveError as e:
            print(f"{prog}: {e}", file=sys.stderr)
            self.robot = None
        self.offers = self._offers()

    def _offers(self) -> list[tuple[Any, Any]]:
        from miro_gen.live.remote import LiveError

        if self.robot is None:
            return []
        try:
            return self.robot.offers(self.topics)
        except LiveError:  # no naming service yet: the channel is waited for, and said so
            return []

    def channel_names(self) -> list[str]:
        """The channels the suppliers publish on (of their offers), each once."""
        return sorted({o.channel for _, o in self.offers})

    def decodable(self, type_hash: str) -> None:
        """Make the events of `type_hash` decodable here when no generated type has it: with
        the data schema a supplier of it gives (looked for once, its offers asked again when
        it was not among them)."""
        from miro_gen.eventlog.types import types_from_schemas
        from miro_gen.live.remote import LiveError
        from miro_gen.runtime import registry

        if not type_hash or type_hash in self.tried or registry.find(type_hash) is not None:
            return
        self.tried.add(type_hash)
        offers = [(s, o) for s, o in self.offers if o.type_hash == type_hash]
        if not offers:
            self.offers = self._offers()
            offers = [(s, o) for s, o in self.offers if o.type_hash == type_hash]
        for service, offer in offers:
            assert self.robot is not None  # offers come from it
            try:
                schema = self.robot.data_schema(service, type_hash)
            except LiveError:
                continue
            why = types_from_schemas([schema])
            if why is not None:
                topic = f"{offer.domain}/{offer.type_name}"
                print(f"{self.prog}: cannot decode {topic}: {why}", file=sys.stderr)
            return

    def close(self) -> None:
        if self.robot is not None:
            self.robot.close()


def _listen(
    p: argparse.ArgumentParser, prog: str, argv: Sequence[str], given: str | None, names: list[str]
) -> tuple[Any, list[Any]] | None:
    """A Server for the tool and the channels to listen on: the one `given`; else those of
    `names` (the suppliers') bound now and EventChannel (where suppliers that do not describe
    themselves, a log's replay, a bridge, publish), or EventChannel waited for when none is.
    None when Ctrl-C comes while waiting."""
    import MiroNaming

    from miro_gen.cli.eventargs import make_server
    from miro_gen.exceptions import SystemException

    if given is not None:
        found = server_and_channel(p, prog, argv, given)
        return None if found is None else (found[0], [found[1]])
    server = make_server(p, prog, argv)
    channels: dict[str, Any] = {}
    for name in [*names, DEFAULT_CHANNEL]:
        try:
            channel = server.resolve_channel(name)
        except (MiroNaming.NotFound, SystemException):  # an offer its channel outlived
            continue
        channels.setdefault(channel.name, channel)
    if channels:
        return server, list(channels.values())
    try:
        return server, [resolve_or_wait(server, DEFAULT_CHANNEL, prog)]
    except KeyboardInterrupt:
        server.close()
        return None


def echo_parser() -> argparse.ArgumentParser:
    """`miro echo`'s options (its run and shell completion read them)."""
    p = _parser(
        "miro echo", "Print the events of TOPIC as they arrive, decoded, and sequence gaps."
    )
    p.add_argument("-n", "--count", type=int, default=0, help="exit after N events")
    add_length_options(p)
    return p


def hz_parser() -> argparse.ArgumentParser:
    """`miro hz`'s options (its run and shell completion read them)."""
    p = _parser(
        "miro hz",
        "Print, every second, the rate at which the events of TOPIC arrive, the min, max and "
        "standard deviation of the period, their lag (how long after their push they arrive: "
        "a consumer that falls behind sees it grow), the events missed (sequence gaps: "
        "dropped on the way, or by a supplier while its channel was gone) and the bandwidth "
        "(payload bytes a second).",
    )
    p.add_argument("-w", "--window", type=int, default=100, help="periods averaged (default 100)")
    return p


def echo_main(argv: Sequence[str]) -> int:
    if wants_ros2(argv):
        from miro_gen.cli import live_ros2

        return live_ros2.echo_main(argv)
    prog = "miro echo"
    p = echo_parser()
    ns = p.parse_args(split_common(p, argv))
    limit = length_limit(p, ns)
    from miro_gen.eventlog.show import clock_text, payload_text
    from miro_gen.transport.events.frames import RawEvent
    from miro_gen.transport.events.gaps import GapCounter

    suppliers = Suppliers(prog, argv, ns.topics)
    for _, offer in suppliers.offers:
        suppliers.decodable(offer.type_hash)
    found = _listen(p, prog, argv, ns.channel, suppliers.channel_names())
    if found is None:
        suppliers.close()
        return 0
    server, channels = found
    server.on_shutdown(suppliers.close)
    gaps = GapCounter()
    shown = [0]

    def show(events: list[RawEvent], received_ns: int) -> None:
        lines = []
        for e in events:
            if ns.count and shown[0] >= ns.count:
                break
            topic = f"{e.domain}/{e.type_name}"
            missed = gaps.observe(e.supplier, e.type_name, e.seq)
            if missed:
                lines.append(f"-- {missed} missed on {topic} before #{e.seq}")
            suppliers.decodable(e.type_hash)  # a supplier that came later: asked once
            text = payload_text(e.type_hash, e.data, limit)
            lines.append(f"{clock_text(e.stamp_ns)} {topic} #{e.seq} {text}")
            shown[0] += 1
        if lines:
            print("\n".join(lines), flush=True)
        if ns.count and shown[0] >= ns.count:
            server.shutdown()

    for channel in channels:
        _tap(server, channel, ns.topics, show)
    server.run()
    return 0


def hz_main(argv: Sequence[str]) -> int:
    if wants_ros2(argv):
        from miro_gen.cli import live_ros2

        return live_ros2.hz_main(argv)
    prog = "miro hz"
    p = hz_parser()
    ns = p.parse_args(split_common(p, argv))
    if ns.window < 1:
        p.error("--window must be 1 or more")
    from miro_gen.eventlog.rates import RateWindow, data_rate
    from miro_gen.transport.events.frames import RawEvent
    from miro_gen.transport.events.gaps import GapCounter

    names: list[str] = []
    if ns.channel is None:
        suppliers = Suppliers(prog, argv, ns.topics)
        names = suppliers.channel_names()
        suppliers.close()
    found = _listen(p, prog, argv, ns.channel, names)
    if found is None:
        return 0
    server, channels = found
    windows: dict[str, RateWindow] = {}
    gaps: dict[str, GapCounter] = {}

    def arrived(events: list[RawEvent], received_ns: int) -> None:
        t = received_ns / 1e9
        for e in events:
            topic = f"{e.domain}/{e.type_name}"
            window = windows.get(topic)
            if window is None:
                if len(windows) >= MAX_TOPICS:  # a bounded table, whatever the channel carries
                    continue
                window = windows[topic] = RateWindow(ns.window)
                gaps[topic] = GapCounter()
            window.add(t, len(e.data), (received_ns - e.publish_ns) / 1e9)
            gaps[topic].observe(e.supplier, e.type_name, e.seq)

    def report(_: object = None) -> None:
        if not windows:
            print("no events yet", flush=True)
            return
        for topic in sorted(windows):
            stats = windows[topic].stats()
            missed = gaps[topic].missed
            if stats is None:
                print(f"{topic}: 1 event", flush=True)
                continue
            rate, low, high, std = stats
            lag_mean, lag_max = windows[topic].lag() or (0.0, 0.0)
            bandwidth = data_rate(windows[topic].bandwidth() or 0.0)
            print(
                f"{topic}: {rate:.2f} Hz  min {low:.4f} s  max {high:.4f} s  "
                f"std {std:.4f} s  window {len(windows[topic].periods)}  "
                f"lag {lag_mean * 1000:.1f} ms (max {lag_max * 1000:.1f})  missed {missed}  "
                f"{bandwidth}",
                flush=True,
            )

    for channel in channels:
        _tap(server, channel, ns.topics, arrived)
    server.reactor().schedule_timer(1.0, 1.0, report)
    server.run()
    return 0
