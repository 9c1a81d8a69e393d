"""ROS 2 names as the DDS RMWs spell them on the wire, and back (no I/O).

ros2/rmw_dds_common and the RMWs of ROS 2 Kilted (rmw_fastrtps `names.hpp`, `namespace_prefix`,
rmw_cyclonedds `rmw_node.cpp`) put a prefix before every ROS name: `rt` for topics, `rq` and `rr`
for a service's request and reply topics, whose names also end in `Request` and `Reply`. A ROS
type `pkg/msg/Name` is the DDS type `pkg::msg::dds_::Name_`; a service's request and response are
`pkg::srv::dds_::Name_Request_` and `..._Response_`.
"""

from __future__ import annotations

import re

TOPIC_PREFIX = "rt"
REQUEST_PREFIX = "rq"
REPLY_PREFIX = "rr"
REQUEST_SUFFIX = "Request"
REPLY_SUFFIX = "Reply"

# A fully qualified ROS name: tokens of letters, digits and underscores after each `/`, none
# starting with a digit, no `__` and no trailing `_`-free rules beyond rcl's basic ones.
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


class Ros2NameError(ValueError):
    """A ROS name, node name or type name that ROS 2 would refuse (the message says why)."""


def expand_topic(name: str, namespace: str = "/", node: str = "") -> str:
    """The fully qualified form of a topic or service name, as rcl expands it: relative names
    are put in the node's namespace, `~` stands for the node's own name."""
    if not name:
        raise Ros2NameError("a ROS name cannot be empty")
    if name.startswith("~"):
        if not node:
            raise Ros2NameError(f"{name!r}: '~' needs a node name")
        name = join(namespace, node) + name[1:]
    elif not name.startswith("/"):
        name = join(namespace, name)
    check_name(name)
    return name


def join(namespace: str, name: str) -> str:
    """`namespace/name`, with exactly one `/` between them."""
    return namespace.rstrip("/") + "/" + name.strip("/")


def check_name(name: str) -> None:
    """Refuse a fully qualified name rcl would refuse."""
    if not name.startswith("/") or (name != "/" and name.endswith("/")):
        raise Ros2NameError(f"{name!r} is not a fully qualified ROS name (/a/b)")
    for token in name.strip("/").split("/"):
        if not _TOKEN.match(token) or "__" in token:
            raise Ros2NameError(f"{name!r}: {token!r} is not a valid ROS name token")


def check_node_name(name: str) -> None:
    if not _TOKEN.match(name):
        raise Ros2NameError(f"{name!r} is not a valid ROS node name")


def check_namespace(namespace: str) -> None:
    if namespace != "/":
        check_name(namespace)


def topic_to_dds(name: str) -> str:
    """`/chatter` → `rt/chatter`."""
    return TOPIC_PREFIX + name


def service_to_dds(name: str) -> tuple[str, str]:
    """A service's request and reply topics: `/add` → (`rq/addRequest`, `rr/addReply`)."""
    return REQUEST_PREFIX + name + REQUEST_SUFFIX, REPLY_PREFIX + name + REPLY_SUFFIX


def type_to_dds(ros_type: str) -> str:
    """`std_msgs/msg/String` → `std_msgs::msg::dds_::String_` (the DDS type name)."""
    parts = ros_type.split("/")
    if len(parts) < 2 or not all(_TOKEN.match(p) for p in parts):
        raise Ros2NameError(f"{ros_type!r} is not a ROS type name (pkg/msg/Name)")
    return "::".join([*parts[:-1], "dds_", parts[-1] + "_"])


def type_from_dds(dds_type: str) -> str | None:
    """`std_msgs::msg::dds_::String_` → `std_msgs/msg/String`; None for a type not named by
    the RMW convention."""
    parts = dds_type.split("::")
    if len(parts) < 3 or parts[-2] != "dds_" or not parts[-1].endswith("_"):
        return None
    return "/".join([*parts[:-2], parts[-1][:-1]])


def ros_type_of(type_name: str) -> str:
    """The ROS type name of an IDL scoped name `pkg::msg::Name` (`pkg/msg/Name`)."""
    return "/".join(type_name.split("::"))


def topic_from_dds(dds_topic: str) -> tuple[str, str] | None:
    """What a DDS topic is to ROS: ("topic", "/chatter") for `rt/chatter`, ("service",
    "/add") for either of a service's topics; None for a topic outside the ROS conventions."""
    if dds_topic.startswith(TOPIC_PREFIX + "/"):
        return "topic", dds_topic[len(TOPIC_PREFIX) :]
    for prefix, suffix in ((REQUEST_PREFIX, REQUEST_SUFFIX), (REPLY_PREFIX, REPLY_SUFFIX)):
        if dds_topic.startswith(prefix + "/") and dds_topic.endswith(suffix):
            return "service", dds_topic[len(prefix) : -len(suffix)]
    return None


def service_type_from_dds(dds_type: str) -> str | None:
    """`pkg::srv::dds_::Name_Request_` (or `_Response_`) → `pkg/srv/Name`."""
    ros = type_from_dds(dds_type)
    if ros is None:
        return None
    for suffix in ("_Request", "_Response"):
        if ros.endswith(suffix):
            return ros[: -len(suffix)]
    return None
