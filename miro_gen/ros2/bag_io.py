"""Recording ROS 2 topics into a rosbag2 MCAP file, and playing one back onto ROS 2 topics, as
`ros2 bag record` and `ros2 bag play` do (`miro log record --ros2`, `miro log play` of a
rosbag2 file). The file's layout is ros2/bag.py's.

Both need the generated class of each topic's type on the module path (miro-idl of the
interfaces' `.msg` files), as rosbag2 needs the type support of each type installed: it names
the type to DDS. The payloads go through as they are, never decoded.
"""

from __future__ import annotations

import heapq
import re
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from miro_gen.eventlog.reader import LogReader
from miro_gen.ros2 import names
from miro_gen.ros2 import qos as ros_qos
from miro_gen.ros2.bag import BagWriter, message_class
from miro_gen.ros2.node import Node, Publisher


class BagRecorder:
    """Subscribes the ROS 2 topics `wanted` (all when empty) as they appear on the graph, and
    writes what arrives into `writer` (receive time as log time, the source's send time as
    publish time). `poll()` looks at the graph again; call it now and then."""

    def __init__(
        self, node: Node, writer: BagWriter, wanted: Iterable[str] = (),
        profile: ros_qos.QosProfile = ros_qos.DEFAULT,
    ) -> None:  # fmt: skip
        self.node = node
        self.writer = writer
        self.wanted = set(wanted)
        self.profile = profile
        self.recording: dict[str, str] = {}  # topic -> ROS type
        self.skipped: dict[str, str] = {}  # topic -> why it is not recorded

    def poll(self) -> None:
        for topic, types in self.node.graph.topics().items():
            if topic in self.recording or topic in self.skipped:
                continue
            if self.wanted and topic not in self.wanted:
                continue
            found = [(t, message_class(t)) for t in types]
            usable = [(t, c) for t, c in found if c is not None]
            if not usable:
                self.skipped[topic] = (
                    f"no generated type here for {', '.join(types)} (compile its .msg with "
                    "miro-idl and put it on PYTHONPATH)"
                )
                continue
            rtype, cls = usable[0]
            assert cls is not None
            self.writer.add_topic(topic, cls, self.profile)
            self.node.reader(
                cls, names.topic_to_dds(topic), self.profile, cls._ros2_type_hash,
                self._handler(topic),
            )  # fmt: skip
            self.recording[topic] = rtype

    def _handler(self, topic: str) -> Callable[[bytes, Any], None]:
        write = self.writer.write

        def on_sample(data: bytes, info: Any) -> None:
            write(topic, data, time.time_ns(), int(getattr(info, "source_timestamp", 0) or 0))

        return on_sample


_RELIABILITY = re.compile(r"reliability:\s*(\S+)")
_DURABILITY = re.compile(r"durability:\s*(\S+)")


def offered_profile(qos_yaml: str) -> ros_qos.QosProfile:
    """The QoS to play a topic with, from its `offered_qos_profiles` (the first profile's
    reliability and durability; numbers or names, as rosbag2 writes either): the default
    profile otherwise."""
    profile = ros_qos.DEFAULT
    rel, dur = _RELIABILITY.search(qos_yaml), _DURABILITY.search(qos_yaml)
    if rel and rel.group(1).strip("'\"") in ("2", "best_effort"):
        profile = ros_qos.QosProfile(depth=profile.depth, reliable=False)
    if dur and dur.group(1).strip("'\"") in ("1", "transient_local"):
        profile = ros_qos.QosProfile(profile.depth, profile.reliable, transient_local=True)
    return profile


class BagPlayer:
    """Publishes the messages of rosbag2 files on their ROS 2 topics at the pace they were
    recorded (times `rate`), from the node `node`. Topics without a generated type here are
    left out (`skipped` says why)."""

    def __init__(self, node: Node, logs: list[LogReader], wanted: Iterable[str] = ()) -> None:
        self.node = node
        self.logs = logs
        self.publishers: dict[str, Publisher[Any]] = {}
        self.skipped: dict[str, str] = {}
        self.sent = 0
        want = set(wanted)
        for log in logs:
            for topic in log.topics():
                name = topic.topic
                if not topic.ros2 or (want and name not in want) or name in self.publishers:
                    continue
                cls = message_class(topic.type_name, topic.type_hash)
                if cls is None:
                    self.skipped[name] = f"no generated type here for {topic.type_name}"
                    continue
                meta = _channel_metadata(log, topic.id)
                profile = offered_profile(meta.get("offered_qos_profiles", ""))
                self.publishers[name] = node.publisher(cls, name, profile)

    def play(
        self, rate: float = 1.0, start_ns: int | None = None, end_ns: int | None = None,
        stop: threading.Event | None = None,
    ) -> int:  # fmt: skip
        """Publish once through (the files' messages merged in log-time order); the number
        published. Returns early when `stop` is set."""
        stop = stop or threading.Event()
        streams = [log.messages(list(self.publishers), start_ns, end_ns) for log in self.logs]
        merged = heapq.merge(*streams, key=lambda item: item[1].log_time)
        first: int | None = None
        began = time.monotonic()
        sent = 0
        for topic, message in merged:
            if first is None:
                first = message.log_time
            due = began + (message.log_time - first) / 1e9 / rate
            wait = due - time.monotonic()
            if wait > 0 and stop.wait(wait):
                break
            if stop.is_set():
                break
            self.publishers[topic.topic].publish_raw(message.data)
            sent += 1
        self.sent += sent
        return sent


def _channel_metadata(log: LogReader, channel_id: int) -> dict[str, str]:
    summary = log.summary
    if summary is None or channel_id not in summary.channels:
        return {}
    return dict(summary.channels[channel_id].metadata)
