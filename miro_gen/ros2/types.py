"""What the ROS 2 side needs of a generated type (`_data_schema`, `_ros2_type`,
`_ros2_type_hash`, `serialize`, `deserialize`), and the request and response classes of a
generated service type (no I/O)."""

from __future__ import annotations

from typing import Any, ClassVar, Protocol, Self

from miro_gen.ros2 import names


class Message(Protocol):
    """A generated struct: every class miro-idl makes of a ROS 2 interface is one."""

    _type_name: ClassVar[str]
    _data_schema: ClassVar[str]
    _ros2_type: ClassVar[str]
    _ros2_type_hash: ClassVar[str]

    def serialize(self) -> bytes: ...

    @classmethod
    def deserialize(cls, data: bytes | bytearray | memoryview) -> Self: ...


def ros_type(cls: type[Message]) -> str:
    """`pkg/msg/Name`: the class's ROS 2 type, or what its IDL name says (`pkg::msg::Name`)."""
    return cls._ros2_type or names.ros_type_of(cls._type_name)


def dds_type(cls: type[Message]) -> str:
    return names.type_to_dds(ros_type(cls))


def service_parts(srv: type[Message]) -> tuple[type[Any], type[Any]]:
    """The request and response classes of a generated service type (`pkg/srv/Name`, whose
    members `request_message` and `response_message` are typed with them)."""
    try:
        probe: Any = srv()
        return type(probe.request_message), type(probe.response_message)
    except (AttributeError, TypeError):
        raise TypeError(f"{srv.__name__} is not a generated ROS 2 service type") from None
