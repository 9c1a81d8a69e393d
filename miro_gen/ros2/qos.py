"""ROS 2 QoS profiles (rmw's `rmw_qos_profile_*`, rclpy's `qos_profile_*`) and the DDS QoS the
RMWs make of them (no I/O).

Endpoints also carry in USER_DATA the RIHS01 hash of their type as rmw_dds_common writes it
(`typehash=RIHS01_<hex>;`), from which peers' graphs learn endpoint types' hashes; payloads are
XCDR1 (the data representation the RMWs announce).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from cyclonedds.qos import Policy, Qos

# What a reliable writer may block for when its history is full (rmw's default: 100 ms in
# rmw_cyclonedds; Fast DDS's own default), in nanoseconds.
MAX_BLOCKING_NS = 100_000_000


@dataclass(frozen=True)
class QosProfile:
    """A ROS 2 QoS profile: history (keep last `depth`, or keep all), reliability, durability."""

    depth: int = 10
    reliable: bool = True
    transient_local: bool = False
    keep_all: bool = False

    def with_depth(self, depth: int) -> QosProfile:
        return replace(self, depth=depth)

    def describe(self) -> str:
        history = "keep all" if self.keep_all else f"keep last {self.depth}"
        return ", ".join(
            (
                history,
                "reliable" if self.reliable else "best effort",
                "transient local" if self.transient_local else "volatile",
            )
        )


DEFAULT = QosProfile()  # rmw_qos_profile_default: keep last 10, reliable, volatile
SENSOR_DATA = QosProfile(depth=5, reliable=False)  # rmw_qos_profile_sensor_data
SERVICES = QosProfile()  # rmw_qos_profile_services_default
PARAMETER_EVENTS = QosProfile(depth=1000)  # rmw_qos_profile_parameter_events
# What the RMWs use for `ros_discovery_info`: a late joiner gets each participant's last state.
DISCOVERY_INFO = QosProfile(depth=1, transient_local=True)

PROFILES = {
    "default": DEFAULT,
    "sensor_data": SENSOR_DATA,
    "services_default": SERVICES,
    "parameter_events": PARAMETER_EVENTS,
}


def type_hash_user_data(ros2_type_hash: str) -> bytes:
    """USER_DATA of an endpoint as rmw_dds_common encodes a type hash (empty if none)."""
    return f"typehash={ros2_type_hash};".encode() if ros2_type_hash else b""


def parse_user_data(data: bytes) -> dict[str, str]:
    """`key=value;` pairs of a USER_DATA (the RMWs' format), values as text."""
    out: dict[str, str] = {}
    for item in data.decode("utf-8", "replace").split(";"):
        key, eq, value = item.partition("=")
        if eq and key:
            out[key] = value
    return out


def dds_qos(profile: QosProfile, user_data: bytes = b"") -> Qos:
    """The cyclonedds QoS of an endpoint with `profile`."""
    policies = [
        Policy.Reliability.Reliable(MAX_BLOCKING_NS)
        if profile.reliable
        else Policy.Reliability.BestEffort,
        Policy.History.KeepAll if profile.keep_all else Policy.History.KeepLast(profile.depth),
        Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if user_data:
        policies.append(Policy.Userdata(user_data))
    return Qos(*policies)
