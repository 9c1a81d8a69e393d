"""A ROS 2 node in a miro process: publishers and subscriptions of ROS 2 topics over DDS, as
rclpy nodes see them (names, types, QoS and the graph as the RMWs of ROS 2 Kilted make them).

A `Context` is what rclpy's context is: one DDS participant (ros2/domain.py) shared by its
nodes, the thread that delivers what arrives (handlers run on it, one at a time) and this
process's entry on `ros_discovery_info`. Services and clients are in ros2/services.py.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from miro_gen.ros2 import names
from miro_gen.ros2 import qos as ros_qos
from miro_gen.ros2.domain import Participant
from miro_gen.ros2.endpoints import Dispatcher, RawReader, RawWriter, Topics
from miro_gen.ros2.graph import GraphAnnouncer, GraphView
from miro_gen.ros2.rtps.participant import RtpsParticipant
from miro_gen.ros2.types import Message, dds_type

M = TypeVar("M", bound=Message)
_keys = itertools.count(1)


class Context:
    """One DDS participant of the ROS 2 domain and what its nodes share."""

    def __init__(self, domain_id: int | None = None) -> None:
        self.participant = Participant(domain_id)
        self.topics = Topics(self.participant)
        self.dispatcher = Dispatcher(self.participant)
        self.announcer = GraphAnnouncer(self.participant, self.topics)
        self._graph: GraphView | None = None
        self._rtps: RtpsParticipant | None = None
        self._lock = threading.Lock()

    @property
    def graph(self) -> GraphView:
        """The graph as discovery and `ros_discovery_info` tell it (made when first asked)."""
        with self._lock:
            if self._graph is None:
                self._graph = GraphView(self.participant, self.topics, self.dispatcher)
            return self._graph

    @property
    def rtps(self) -> RtpsParticipant:
        """Our own RTPS participant (ros2/rtps), for what Fast DDS peers need and cyclonedds
        cannot give them: service replies with their request's identity (made when first
        asked: a service makes it)."""
        with self._lock:
            if self._rtps is None:
                self._rtps = RtpsParticipant(self.participant.domain_id, b"enclave=/;")
            return self._rtps

    def close(self) -> None:
        with self._lock:
            rtps, self._rtps = self._rtps, None
        if rtps is not None:
            rtps.close()
        self.dispatcher.stop()
        self.participant.close()

    def __enter__(self) -> Context:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Node:
    """A ROS 2 node: `Node("talker")`, then `publisher(...)`, `subscription(...)`, and
    (ros2/services.py) `service(...)`, `client(...)`."""

    def __init__(self, name: str, namespace: str = "/", context: Context | None = None) -> None:
        names.check_node_name(name)
        namespace = "/" + namespace.strip("/") if namespace.strip("/") else "/"
        names.check_namespace(namespace)
        self.name = name
        self.namespace = namespace
        self._own_context = context is None
        self.context = context or Context()
        self.key = next(_keys)
        self._closers: list[Callable[[], None]] = []
        self.context.announcer.add_node(self.key, namespace, name)

    @property
    def graph(self) -> GraphView:
        return self.context.graph

    def resolve(self, name: str) -> str:
        """The fully qualified name of a topic or service name used by this node."""
        return names.expand_topic(name, self.namespace, self.name)

    def publisher(
        self, msg_type: type[M], topic: str, qos: ros_qos.QosProfile = ros_qos.DEFAULT
    ) -> Publisher[M]:
        return Publisher(self, msg_type, self.resolve(topic), qos)

    def subscription(
        self,
        msg_type: type[M],
        topic: str,
        callback: Callable[[M], None],
        qos: ros_qos.QosProfile = ros_qos.DEFAULT,
    ) -> Subscription[M]:
        return Subscription(self, msg_type, self.resolve(topic), callback, qos)

    def raw_subscription(
        self,
        msg_type: type[Message],
        topic: str,
        callback: Callable[[bytes], None],
        qos: ros_qos.QosProfile = ros_qos.DEFAULT,
    ) -> RawSubscription:
        """A subscription handing over each message's CDR bytes undecoded (bridges, logs)."""
        return RawSubscription(self, msg_type, self.resolve(topic), callback, qos)

    def writer(
        self, msg_type: type[Message], dds_topic: str, profile: ros_qos.QosProfile,
        type_hash: str,
    ) -> RawWriter:  # fmt: skip
        """A writer of this node (announced on the graph) on a DDS topic."""
        w = RawWriter(
            self.context.topics, dds_topic, msg_type._data_schema, profile,
            ros_qos.type_hash_user_data(type_hash),
        )  # fmt: skip
        self.context.announcer.add_endpoint(self.key, w.gid, reader=False)
        self._closers.append(lambda: self._drop(w.gid, w.close))
        return w

    def reader(
        self, msg_type: type[Message], dds_topic: str, profile: ros_qos.QosProfile,
        type_hash: str, handler: Callable[[bytes, Any], None],
    ) -> RawReader:  # fmt: skip
        """A reader of this node (announced on the graph) on a DDS topic."""
        ctx = self.context
        r = RawReader(
            ctx.topics, dds_topic, msg_type._data_schema, profile, handler, ctx.dispatcher,
            ros_qos.type_hash_user_data(type_hash),
        )  # fmt: skip
        ctx.announcer.add_endpoint(self.key, r.gid, reader=True)
        self._closers.append(lambda: self._drop(r.gid, r.close))
        return r

    def _drop(self, gid: bytes, close: Callable[[], None]) -> None:
        self.context.announcer.remove_endpoint(self.key, gid)
        close()

    def close(self) -> None:
        for close in reversed(self._closers):
            close()
        self._closers.clear()
        self.context.announcer.remove_node(self.key)
        if self._own_context:
            self.context.close()

    def __enter__(self) -> Node:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Publisher(Generic[M]):
    """Publishes messages of one type on one ROS 2 topic."""

    def __init__(self, node: Node, msg_type: type[M], topic: str, qos: ros_qos.QosProfile) -> None:
        self.topic = topic
        self.msg_type = msg_type
        self._writer = node.writer(
            msg_type, names.topic_to_dds(topic), qos, msg_type._ros2_type_hash
        )
        dds_type(msg_type)  # a type with no ROS 2 name is refused here, before any traffic

    def publish(self, msg: M) -> None:
        self._writer.write(msg.serialize())

    def publish_raw(self, data: bytes | bytearray) -> None:
        """Publish a message already in CDR (with its encapsulation header)."""
        self._writer.write(data)

    def wait_for_acks(self, timeout: float = 10.0) -> bool:
        """Whether every reliable subscription matched took all published, within `timeout` s."""
        return self._writer.wait_for_acks(timeout)

    def subscribers(self) -> int:
        """How many subscriptions this publisher has matched."""
        return self._writer.matched()

    def wait_for_subscribers(self, count: int = 1, timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while self.subscribers() < count:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True


class RawSubscription:
    """Takes the messages of one ROS 2 topic as CDR bytes."""

    def __init__(
        self, node: Node, msg_type: type[Message], topic: str,
        callback: Callable[[bytes], None], qos: ros_qos.QosProfile,
    ) -> None:  # fmt: skip
        self.topic = topic
        self.msg_type = msg_type
        self._callback = callback
        self._reader = node.reader(
            msg_type, names.topic_to_dds(topic), qos, msg_type._ros2_type_hash, self._on_data
        )

    def _on_data(self, data: bytes, info: Any) -> None:
        self._callback(data)

    def publishers(self) -> int:
        return self._reader.matched()

    def wait_for_publishers(self, count: int = 1, timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while self.publishers() < count:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True


class Subscription(RawSubscription, Generic[M]):
    """Calls `callback` with each message of one ROS 2 topic, decoded; a message that does
    not decode is logged and dropped."""

    def __init__(
        self, node: Node, msg_type: type[M], topic: str, callback: Callable[[M], None],
        qos: ros_qos.QosProfile,
    ) -> None:  # fmt: skip
        self._decode = msg_type.deserialize
        self._typed = callback
        super().__init__(node, msg_type, topic, self._deliver, qos)

    def _deliver(self, data: bytes) -> None:
        self._typed(self._decode(data))
