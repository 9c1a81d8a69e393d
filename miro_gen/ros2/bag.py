"""rosbag2's MCAP profile (rosbag2_storage_mcap, ROS 2 Kilted): what a rosbag2 file holds and
how miro writes one (no DDS here: the recorder and the player are ros2/bag_record.py and
ros2/bag_play.py).

A rosbag2 MCAP file has the profile `ros2`; a schema per message type, named `pkg/msg/Name`,
whose encoding is `ros2msg` (the type's `.msg` text, then each type it uses after a line of 80
`=` and `MSG: pkg/Name`) or `ros2idl`; a channel per ROS topic (`/chatter`), with the message
encoding `cdr` and the metadata `offered_qos_profiles` (the publishers' QoS as YAML) and
`topic_type_hash` (RIHS01); and messages whose payload is the CDR a DDS RMW sends, with the
encapsulation header, the receive time as log time and the send time as publish time.

The `.msg` text of a generated type is made from its data schema (ros2/schema.py): constants
and default values are not in it (a reader needs neither to decode), the rest is as rosidl
reads it.
"""

from __future__ import annotations

import importlib
import os
import threading
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from miro_gen import __version__
from miro_gen.eventlog.reader import ROS2_SCHEMA_ENCODINGS
from miro_gen.ros2 import names, schema
from miro_gen.ros2 import qos as ros_qos
from miro_gen.ros2.types import Message, ros_type

PROFILE = "ros2"
SCHEMA_ENCODINGS = ROS2_SCHEMA_ENCODINGS  # what the log reader takes as ROS 2 topics
MESSAGE_ENCODING = "cdr"
SEPARATOR = "=" * 80
EMPTY_MEMBER = "structure_needs_at_least_one_member"  # rosidl's member of an empty message
CHUNK_BYTES = 1 << 20

_MSG_PRIMITIVES = {
    "boolean": "bool",
    "octet": "byte",
    "char": "char",
    "short": "int16",
    "unsigned short": "uint16",
    "long": "int32",
    "unsigned long": "uint32",
    "long long": "int64",
    "unsigned long long": "uint64",
    "float": "float32",
    "double": "float64",
}


def msg_definition(cls: type[Message]) -> str:
    """The `ros2msg` schema of a generated type: its `.msg` text and its dependencies'."""
    parsed = schema.read(cls._data_schema)
    top = parsed.top
    parts = [_msg_text(top)]
    for struct in parsed.structs.values():
        if struct is not top:
            parts.append(f"{SEPARATOR}\nMSG: {_msg_name(struct.scoped)}\n{_msg_text(struct)}")
    return "\n".join(parts)


def _msg_text(struct: schema.Struct) -> str:
    members = struct.members
    if len(members) == 1 and members[0].name == EMPTY_MEMBER:
        return ""
    return "".join(f"{_msg_type(m.type)} {m.name}\n" for m in members)


def _msg_name(scoped: str) -> str:
    """`pkg::msg::Name` → `pkg/Name`, as rosbag2 names the types a definition uses."""
    parts = scoped.split("::")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 else "/".join(parts)


def _msg_type(ref: schema.TypeRef) -> str:
    match ref:
        case schema.Primitive(name):
            return _MSG_PRIMITIVES.get(name, name)
        case schema.String(bound, wide):
            base = "wstring" if wide else "string"
            return base if bound is None else f"{base}<={bound}"
        case schema.Sequence(element, bound):
            return f"{_msg_type(element)}[{'' if bound is None else f'<={bound}'}]"
        case schema.Array(element, dims) if len(dims) == 1:
            return f"{_msg_type(element)}[{dims[0]}]"
        case schema.Named(scoped):
            return _msg_name(scoped)
    raise schema.SchemaError(f"{ref} has no .msg form")


def qos_yaml(profile: ros_qos.QosProfile) -> str:
    """`offered_qos_profiles` of a channel: one profile as rosbag2 writes it (rmw's enum
    values; deadline, lifespan and lease infinite)."""
    infinite = "    sec: 9223372036\n    nsec: 854775807\n"
    return (
        f"- history: {2 if profile.keep_all else 1}\n"
        f"  depth: {0 if profile.keep_all else profile.depth}\n"
        f"  reliability: {1 if profile.reliable else 2}\n"
        f"  durability: {1 if profile.transient_local else 2}\n"
        f"  deadline:\n{infinite}"
        f"  lifespan:\n{infinite}"
        "  liveliness: 1\n"
        f"  liveliness_lease_duration:\n{infinite}"
        "  avoid_ros_namespace_conventions: false\n"
    )


def message_class(ros_type_name: str, type_hash: str = "") -> type[Message] | None:
    """The generated class of a ROS type (`pkg/msg/Name`, from `pkg.msg`), if one is on the
    module path and, when `type_hash` (RIHS01) is given, has that hash."""
    parts = ros_type_name.split("/")
    if len(parts) != 3 or not all(p.isidentifier() for p in parts):
        return None
    try:
        module = importlib.import_module(f"{parts[0]}.{parts[1]}")
    except Exception:  # not generated here, or a package of that name that is something else
        return None
    cls: Any = getattr(module, parts[2], None)
    if getattr(cls, "_ros2_type", None) != ros_type_name or not hasattr(cls, "_data_schema"):
        return None
    if type_hash and cls._ros2_type_hash and cls._ros2_type_hash != type_hash:
        return None
    return cls  # type: ignore[no-any-return]


class BagWriter:
    """A rosbag2 MCAP file: `add_topic(topic, cls, qos)`, then `write(topic, cdr, ...)` from any
    thread; `finish()` writes the summary and indexes (call it on every way out)."""

    def __init__(self, path: str) -> None:
        self.path = path
        self._file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed by finish()
        self._mcap = Writer(
            self._file,
            chunk_size=CHUNK_BYTES,
            compression=CompressionType.ZSTD,
            enable_data_crcs=True,
        )
        self._mcap.start(profile=PROFILE, library=f"miro-gen/{__version__}")
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self.messages = 0
        self.finished = False

    def add_topic(self, topic: str, cls: type[Message], profile: ros_qos.QosProfile) -> None:
        """A channel for the ROS topic `topic` (fully qualified) of type `cls`."""
        names.check_name(topic)
        rtype = ros_type(cls)
        with self._lock:
            if topic in self._channels:
                return
            sid = self._schemas.get(rtype)
            if sid is None:
                text = msg_definition(cls).encode()
                sid = self._mcap.register_schema(rtype, "ros2msg", text)
                self._schemas[rtype] = sid
            metadata = {"offered_qos_profiles": qos_yaml(profile)}
            if cls._ros2_type_hash:
                metadata["topic_type_hash"] = cls._ros2_type_hash
            cid = self._mcap.register_channel(topic, MESSAGE_ENCODING, sid, metadata)
            self._channels[topic] = cid
            self._sequence[cid] = 0

    def write(self, topic: str, cdr: bytes, received_ns: int, sent_ns: int = 0) -> None:
        """One message of a topic added before: its CDR (with the encapsulation header)."""
        with self._lock:
            if self.finished:
                return
            cid = self._channels[topic]
            self._sequence[cid] += 1
            stamp = sent_ns if 0 < sent_ns < 1 << 64 else received_ns
            self._mcap.add_message(cid, received_ns, cdr, stamp, self._sequence[cid] & 0xFFFFFFFF)
            self.messages += 1

    def size(self) -> int:
        try:
            return os.fstat(self._file.fileno()).st_size
        except (OSError, ValueError):
            return 0

    def finish(self) -> None:
        """Write the summary and indexes and close the file; safe to call twice."""
        with self._lock:
            if self.finished:
                return
            self.finished = True
            self._mcap.finish()  # type: ignore[no-untyped-call]
            self._file.close()
