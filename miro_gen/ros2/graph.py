"""The ROS 2 graph: what this process tells peers about its nodes, and what it learns of
everyone's nodes, topics and services.

DDS discovery says which readers and writers exist (topic, type, QoS, participant); which node
owns them is only on the `ros_discovery_info` topic, where each participant of a DDS RMW
publishes its nodes and their endpoints' gids (rmw_dds_common's ParticipantEntitiesInfo,
reliable, transient local, keep last 1). `GraphAnnouncer` publishes this process's;
`GraphView` reads DCPS built-in topics and everyone's `ros_discovery_info` into the lists
`ros2 node list`, `ros2 topic list -t` and `ros2 service list -t` show.
"""

from __future__ import annotations

import threading
from array import array
from dataclasses import dataclass, field
from typing import Any

from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState
from cyclonedds.qos import Policy
from rmw_dds_common.msg import Gid, NodeEntitiesInfo, ParticipantEntitiesInfo

from miro_gen.ros2 import names
from miro_gen.ros2 import qos as ros_qos
from miro_gen.ros2.domain import Participant, gid_of
from miro_gen.ros2.endpoints import Dispatcher, RawReader, RawWriter, Topics

DISCOVERY_TOPIC = "ros_discovery_info"  # no `rt` prefix: it avoids the ROS conventions
_ALIVE = SampleState.Any | ViewState.Any | InstanceState.Alive


@dataclass
class NodeEntities:
    namespace: str
    name: str
    readers: list[bytes] = field(default_factory=list)
    writers: list[bytes] = field(default_factory=list)


class GraphAnnouncer:
    """This participant's nodes and their endpoints, published on `ros_discovery_info` each
    time they change."""

    def __init__(self, participant: Participant, topics: Topics) -> None:
        self.participant = participant
        self._nodes: dict[int, NodeEntities] = {}
        self._lock = threading.Lock()
        schema = ParticipantEntitiesInfo._data_schema
        self._writer = RawWriter(topics, DISCOVERY_TOPIC, schema, ros_qos.DISCOVERY_INFO)

    def add_node(self, key: int, namespace: str, name: str) -> None:
        with self._lock:
            self._nodes[key] = NodeEntities(namespace, name)
        self.announce()

    def remove_node(self, key: int) -> None:
        with self._lock:
            self._nodes.pop(key, None)
        self.announce()

    def add_endpoint(self, key: int, gid: bytes, reader: bool) -> None:
        with self._lock:
            node = self._nodes[key]
            (node.readers if reader else node.writers).append(gid)
        self.announce()

    def remove_endpoint(self, key: int, gid: bytes) -> None:
        with self._lock:
            node = self._nodes.get(key)
            for gids in (node.readers, node.writers) if node else ():
                if gid in gids:
                    gids.remove(gid)
        self.announce()

    def message(self) -> ParticipantEntitiesInfo:
        with self._lock:
            nodes = [
                NodeEntitiesInfo(
                    n.namespace,
                    n.name,
                    [Gid(_gid_bytes(g)) for g in n.readers],
                    [Gid(_gid_bytes(g)) for g in n.writers],
                )
                for n in self._nodes.values()
            ]
        return ParticipantEntitiesInfo(Gid(_gid_bytes(self.participant.gid)), nodes)

    def announce(self) -> None:
        self._writer.write(self.message().serialize())

    def close(self) -> None:
        self._writer.close()


def _gid_bytes(gid: bytes) -> array[int]:
    return array("B", gid.ljust(16, b"\0")[:16])


@dataclass(frozen=True)
class Endpoint:
    """A reader or writer as discovery describes it."""

    gid: bytes
    participant: bytes
    dds_topic: str
    dds_type: str
    reader: bool
    type_hash: str
    reliable: bool = True
    transient_local: bool = False


class GraphView:
    """What is on the ROS 2 graph: nodes, topics and services, with their types."""

    def __init__(self, participant: Participant, topics: Topics, dispatcher: Dispatcher) -> None:
        self.participant = participant
        self._lock = threading.Lock()
        self._participants: dict[bytes, list[NodeEntities]] = {}
        self._pubs = BuiltinDataReader(participant.dds, BuiltinTopicDcpsPublication)
        self._subs = BuiltinDataReader(participant.dds, BuiltinTopicDcpsSubscription)
        profile = ros_qos.QosProfile(depth=1, transient_local=True, keep_all=True)
        self._info = RawReader(
            topics,
            DISCOVERY_TOPIC,
            ParticipantEntitiesInfo._data_schema,
            profile,
            self._on_info,
            dispatcher,
        )

    def _on_info(self, data: bytes, info: Any) -> None:
        msg = ParticipantEntitiesInfo.deserialize(data)
        nodes = [
            NodeEntities(
                n.node_namespace,
                n.node_name,
                [bytes(g.data) for g in n.reader_gid_seq],
                [bytes(g.data) for g in n.writer_gid_seq],
            )
            for n in msg.node_entities_info_seq
        ]
        with self._lock:
            self._participants[bytes(msg.gid.data)] = nodes

    def endpoints(self) -> list[Endpoint]:
        """Every reader and writer discovery knows of, this process's own included."""
        out = []
        for reader, is_reader in ((self._pubs, False), (self._subs, True)):
            cond = ReadCondition(reader, _ALIVE)
            for sample in reader.read(N=100_000, condition=cond):
                ud = _user_data(sample.qos)
                qos = sample.qos or ()
                out.append(
                    Endpoint(
                        gid_of(sample.key),
                        gid_of(sample.participant_key),
                        sample.topic_name,
                        sample.type_name,
                        is_reader,
                        ros_qos.parse_user_data(ud).get("typehash", ""),
                        Policy.Reliability.BestEffort not in qos,
                        Policy.Durability.TransientLocal in qos,
                    )
                )
        return out

    def nodes(self) -> list[tuple[str, str]]:
        """(namespace, name) of every node announced on the graph, sorted."""
        with self._lock:
            found = {(n.namespace, n.name) for ns in self._participants.values() for n in ns}
        return sorted(found)

    def node_of(self, gid: bytes) -> tuple[str, str] | None:
        with self._lock:
            for nodes in self._participants.values():
                for n in nodes:
                    if gid in n.readers or gid in n.writers:
                        return n.namespace, n.name
        return None

    def topics(self) -> dict[str, list[str]]:
        """ROS topic name → its ROS types, as `ros2 topic list -t` shows them."""
        return self._names("topic")

    def services(self) -> dict[str, list[str]]:
        """ROS service name → its ROS service types."""
        return self._names("service")

    def _names(self, kind: str) -> dict[str, list[str]]:
        found: dict[str, set[str]] = {}
        for ep in self.endpoints():
            what = names.topic_from_dds(ep.dds_topic)
            if what is None or what[0] != kind:
                continue
            if kind == "topic":
                ros_type = names.type_from_dds(ep.dds_type)
            else:
                ros_type = names.service_type_from_dds(ep.dds_type)
            found.setdefault(what[1], set()).add(ros_type or ep.dds_type)
        return {k: sorted(v) for k, v in sorted(found.items())}

    def unannounced(self) -> set[bytes]:
        """Participants that have a `ros_discovery_info` writer but whose nodes have not arrived
        yet (a Fast DDS writer sends a late joiner its last state only seconds later)."""
        own = self.participant.gid
        writers = {
            ep.participant
            for ep in self.endpoints()
            if ep.dds_topic == DISCOVERY_TOPIC and not ep.reader and ep.participant != own
        }
        with self._lock:
            return writers - set(self._participants)

    def topic_endpoints(self, topic: str) -> list[Endpoint]:
        """The readers and writers of the ROS topic `topic` (fully qualified)."""
        dds = names.topic_to_dds(topic)
        return [ep for ep in self.endpoints() if ep.dds_topic == dds]

    def close(self) -> None:
        self._info.close()


def best_available(publishers: list[Endpoint], depth: int = 10) -> ros_qos.QosProfile:
    """The profile a subscription takes to hear every one of `publishers`, and as much as they
    offer (rclpy's "best available", what `ros2 topic echo` uses): reliable unless one of them
    is best effort, transient local if all of them are."""
    return ros_qos.QosProfile(
        depth=depth,
        reliable=all(p.reliable for p in publishers),
        transient_local=bool(publishers) and all(p.transient_local for p in publishers),
    )


def _user_data(qos: Any) -> bytes:
    for policy in qos or ():
        if type(policy).__name__ == "Userdata":
            return bytes(policy.data)
    return b""
