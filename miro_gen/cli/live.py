"""`miro echo TOPIC` and `miro hz TOPIC`: look at the events on a channel as they arrive."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import COMMON, server_and_channel, split_common, topic_arg

MAX_TOPICS = 1000  # topics `miro hz` keeps statistics of


def _parser(prog: str, description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=description + " " + COMMON)
    p.add_argument(
        "topics",
        nargs="+",
        type=topic_arg,
        metavar="TOPIC",
        help="DOMAIN/TYPE, * for any part (robot1/Odometry, */Odometry, robot1/*)",
    )
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    return p


def _tap(server: Any, channel: Any, topics: list[tuple[str, str]], handler: Any) -> Any:
    from miro_gen.eventlog.tap import RawEventTap
    from miro_gen.runtime import registry

    registry.discover()
    return RawEventTap(channel, topics, handler)


def echo_main(argv: Sequence[str]) -> int:
    prog = "miro echo"
    p = _parser(prog, "Print the events of TOPIC as they arrive, decoded, and sequence gaps.")
    p.add_argument("-n", "--count", type=int, default=0, help="exit after N events")
    ns = p.parse_args(split_common(p, argv))
    from miro_gen.eventlog.show import clock_text, payload_text
    from miro_gen.transport.event_frames import RawEvent
    from miro_gen.transport.gaps import GapCounter

    found = server_and_channel(p, prog, argv, ns.channel)
    if found is None:
        return 0
    server, channel = found
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
            text = payload_text(e.type_hash, e.data)
            lines.append(f"{clock_text(e.stamp_ns)} {topic} #{e.seq} {text}")
            shown[0] += 1
        if lines:
            print("\n".join(lines), flush=True)
        if ns.count and shown[0] >= ns.count:
            server.shutdown()

    _tap(server, channel, ns.topics, show)
    server.run()
    return 0


def hz_main(argv: Sequence[str]) -> int:
    prog = "miro hz"
    p = _parser(
        prog,
        "Print, every second, the rate at which the events of TOPIC arrive, the min, max and "
        "standard deviation of the period, their lag (how long after their push they arrive: "
        "a consumer that falls behind sees it grow), the events missed (sequence gaps: "
        "dropped on the way, or by a supplier while its channel was gone) and the bandwidth "
        "(payload bytes a second).",
    )
    p.add_argument("-w", "--window", type=int, default=100, help="periods averaged (default 100)")
    ns = p.parse_args(split_common(p, argv))
    if ns.window < 1:
        p.error("--window must be 1 or more")
    from miro_gen.eventlog.rates import RateWindow, data_rate
    from miro_gen.transport.event_frames import RawEvent
    from miro_gen.transport.gaps import GapCounter

    found = server_and_channel(p, prog, argv, ns.channel)
    if found is None:
        return 0
    server, channel = found
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

    _tap(server, channel, ns.topics, arrived)
    server.reactor().schedule_timer(1.0, 1.0, report)
    server.run()
    return 0
