"""A DDS domain participant configured as the ROS 2 RMWs configure theirs, so that rclpy
nodes (Fast DDS or Cyclone DDS) find it: the domain of `ROS_DOMAIN_ID`, discovery kept on this
host when `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (as ROS 2 Kilted's RMWs do), and the
participant's USER_DATA `enclave=/;`, without which the RMWs leave it out of their graph.

With `LOCALHOST`, the cyclonedds participant uses the loopback interface only, sends no
multicast, and finds peers by unicast on 127.0.0.1 at the ports of participant indices 0 to
`MAX_PARTICIPANT_INDEX` (Fast DDS announces itself the same way: rmw_fastrtps' LOCALHOST
profile, 32 initial peers on 127.0.0.1). There, datagrams of up to 64 KB (the loopback MTU,
Fast DDS's own maximum message size) carry a large sample in a few fragments rather than
cyclonedds' default ~1.3 KB fragments: a 1 MiB image in 17 datagrams instead of 780, which
took an rclpy receiver from 5 to ~80 images/s (bench/bench_ros2.py). `CYCLONEDDS_URI`,
when set, configures the domain instead.
"""

from __future__ import annotations

import os
import uuid

from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.qos import Policy, Qos

MAX_PARTICIPANT_INDEX = 32

_LOOPBACK_CONFIG = """<CycloneDDS><Domain id="any">
<General><Interfaces><NetworkInterface address="127.0.0.1" multicast="false"/></Interfaces>
<AllowMulticast>false</AllowMulticast>
<MaxMessageSize>65500B</MaxMessageSize><FragmentSize>62000B</FragmentSize></General>
<Discovery><ParticipantIndex>auto</ParticipantIndex>
<MaxAutoParticipantIndex>{max_index}</MaxAutoParticipantIndex>
<Peers><Peer address="127.0.0.1"/></Peers></Discovery>
</Domain></CycloneDDS>"""


class Ros2DomainError(RuntimeError):
    """The domain or its configuration cannot be used (the message says why)."""


def domain_id(environ: os._Environ[str] | dict[str, str] | None = None) -> int:
    """`ROS_DOMAIN_ID` (0 when unset), checked as rcl checks it."""
    env = os.environ if environ is None else environ
    text = env.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    if not text.isdigit() or int(text) > 232:
        raise Ros2DomainError(f"ROS_DOMAIN_ID={text!r} is not a domain id (0 to 232)")
    return int(text)


def localhost_only(environ: os._Environ[str] | dict[str, str] | None = None) -> bool:
    env = os.environ if environ is None else environ
    if env.get("ROS_LOCALHOST_ONLY", "") == "1":  # the variable before Jazzy
        return True
    return env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST"


def config(environ: os._Environ[str] | dict[str, str] | None = None) -> str | None:
    """The cyclonedds configuration for this environment (None: cyclonedds' own, from
    `CYCLONEDDS_URI` or its defaults)."""
    env = os.environ if environ is None else environ
    if env.get("CYCLONEDDS_URI") or not localhost_only(env):
        return None
    return _LOOPBACK_CONFIG.format(max_index=MAX_PARTICIPANT_INDEX)


class Participant:
    """A cyclonedds participant of the ROS 2 domain, as the RMWs make one (one per process
    and context, shared by its nodes)."""

    def __init__(self, domain: int | None = None, enclave: str = "/") -> None:
        self.domain_id = domain_id() if domain is None else domain
        cfg = config()
        # The Domain entity holds the configuration while the participant lives.
        self._domain = Domain(self.domain_id, cfg) if cfg is not None else None
        qos = Qos(Policy.Userdata(f"enclave={enclave};".encode()))
        self.dds = DomainParticipant(self.domain_id, qos=qos)
        self.gid = gid_of(self.dds.get_guid())

    def close(self) -> None:
        """Delete the participant and everything made in it (peers see them go at once)."""
        self.dds._delete(self.dds._ref)
        self._domain = None


def gid_of(guid: uuid.UUID) -> bytes:
    """The ROS 2 gid of a DDS entity: its 16-byte GUID (prefix, then entity id)."""
    return guid.bytes
