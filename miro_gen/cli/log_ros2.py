"""`miro log record --ros2` and `miro log play` of rosbag2 files: ROS 2 topics into a rosbag2
MCAP file and back onto ROS 2 topics (miro_gen/ros2/bag_io.py), as `ros2 bag record` and
`ros2 bag play` do. They need the `ros2` extra (the cyclonedds wheel)."""

from __future__ import annotations

import argparse
import glob
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

TICK = 0.5  # seconds between looks at the graph and progress updates


def log_file(path: str) -> str:
    """A log's file: `path`, or the one `.mcap` file of a rosbag2 folder."""
    if os.path.isdir(path):
        found = sorted(glob.glob(os.path.join(glob.escape(path), "*.mcap")))
        if len(found) == 1:
            return found[0]
    return path


def is_rosbag(paths: Sequence[str]) -> bool:
    """Whether the first of these logs is a rosbag2 file (its topics are ROS 2 topics)."""
    from miro_gen.eventlog.reader import LogError, LogReader

    try:
        with LogReader(log_file(paths[0])) as log:
            topics = log.topics()
    except LogError:
        return False  # the miro player says what is wrong with it
    return bool(topics) and all(t.ros2 for t in topics)


@contextmanager
def stopped_by_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT, SIGTERM or SIGHUP while inside the block."""
    stop = threading.Event()
    sigs = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in sigs}
    try:
        yield stop
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def ros2_missing(prog: str) -> bool:
    try:
        import cyclonedds  # noqa: F401
    except ImportError:
        print(f"{prog}: error: ROS 2 needs the ros2 extra: pip install 'miro-gen[ros2]'",
              file=sys.stderr)  # fmt: skip
        return True
    return False


def record_ros2(
    prog: str, output: str, topics: list[tuple[str, str]], *, duration: float = 0.0
) -> int:
    """Record the ROS 2 topics named (all when none) into the rosbag2 MCAP file `output`,
    until a signal, or for `duration` seconds when that is given."""
    if ros2_missing(prog):
        return 1
    from miro_gen.eventlog.progress import StatusLine, human_bytes
    from miro_gen.ros2.bag import BagWriter
    from miro_gen.ros2.bag_io import BagRecorder
    from miro_gen.ros2.node import Node

    wanted = [domain for domain, _ in topics]
    bad = [t for t in wanted if not t.startswith("/")]
    if bad:
        print(f"{prog}: error: {bad[0]} is not a ROS 2 topic (/name)", file=sys.stderr)
        return 2
    try:
        writer = BagWriter(output)
    except OSError as e:
        print(f"{output}: error: cannot write: {e.strerror or e}", file=sys.stderr)
        return 1
    status = StatusLine()
    told: set[str] = set()
    started = time.monotonic()
    try:
        with stopped_by_signals() as stop, Node("miro_log_record") as node:
            recorder = BagRecorder(node, writer, wanted)
            shown = " ".join(wanted) or "every ROS 2 topic"
            print(f"recording {shown} into {output} (rosbag2)", file=sys.stderr)
            ends = started + duration if duration > 0 else float("inf")
            while not stop.is_set() and time.monotonic() < ends:
                recorder.poll()
                for topic, why in recorder.skipped.items():
                    if topic not in told:
                        told.add(topic)
                        status.done(f"{prog}: warning: {topic} not recorded: {why}")
                status.update(
                    f"recording {output}: {len(recorder.recording)} topics, "
                    f"{writer.messages} messages, {human_bytes(writer.size())}"
                )
                stop.wait(min(TICK, max(0.0, ends - time.monotonic())))
            node.context.dispatcher.drain()  # what arrived and was not written yet
    finally:
        writer.finish()
    status.done(f"{output}: {writer.messages} messages in {time.monotonic() - started:.1f} s")
    return 0


def play_ros2(prog: str, ns: Any) -> int:
    """Play rosbag2 files onto ROS 2 topics: --rate, --loop, --start/--end, --topics and
    --wait of `miro log play` apply."""
    if ros2_missing(prog):
        return 1
    from miro_gen.eventlog.reader import LogError, LogReader
    from miro_gen.ros2.bag_io import BagPlayer
    from miro_gen.ros2.node import Node

    logs: list[LogReader] = []
    try:
        for path in ns.files:
            try:
                logs.append(LogReader(log_file(path)))
            except LogError as e:
                print(f"{path}: error: {e}", file=sys.stderr)
                return 1
        wanted = [d for d, _ in ns.topics or []]
        excluded = {d for d, _ in ns.exclude}
        first = min((log.span()[0] for log in logs), default=0)
        start = first + int(ns.start * 1e9) if ns.start else None
        end = first + int(ns.end * 1e9) if ns.end is not None else None
        with stopped_by_signals() as stop, Node("miro_log_play") as node:
            player = BagPlayer(node, logs, wanted)
            for topic in excluded:
                player.publishers.pop(topic, None)
            for topic, why in player.skipped.items():
                print(f"{prog}: warning: {topic} not played: {why}", file=sys.stderr)
            if not player.publishers:
                print(f"{prog}: error: no topic to play", file=sys.stderr)
                return 1
            print(
                f"playing {' '.join(ns.files)} onto {len(player.publishers)} ROS 2 topics at "
                f"x{ns.rate:g}",
                file=sys.stderr,
            )
            stop.wait(ns.wait)
            while not stop.is_set():
                if not player.play(ns.rate, start, end, stop) or not ns.loop:
                    break
            print(f"{prog}: {player.sent} messages played", file=sys.stderr)
    except LogError as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 1
    finally:
        for log in logs:
            log.close()
    return 0


def add_ros2_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--ros2",
        action="store_true",
        help="record ROS 2 topics (TOPIC is a ROS name, /chatter; default all) into a rosbag2 "
        "MCAP file that ros2 bag and rosbags read; the topics' types must be generated here "
        "(miro-idl on their .msg files)",
    )
