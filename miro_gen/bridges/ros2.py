"""Relaying between a miro-gen event channel and ROS 2 topics (`miro bridge ros2`).

Towards ROS 2, the events of chosen `domain/type` subscriptions whose payload is a ROS 2 type
(a class miro-idl made of a `.msg`) are published on a ROS 2 topic, each route its own; from
ROS 2, each message of a chosen topic is pushed into the channel as an event of the name given,
in the bridge's domain. The ROS 2 side is a node of its own (miro_gen/ros2), so rclpy nodes see
the bridge, its publishers and its subscriptions on their graph.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from miro_gen.log import PeerWarnings, logger
from miro_gen.ros2.bag import message_class
from miro_gen.ros2.node import Node, Publisher
from miro_gen.runtime import registry
from miro_gen.transport.events import (
    KEEP_ALL,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)


class RouteError(ValueError):
    """A route that cannot be set up (the message says why)."""


@dataclass
class Routes:
    """`to_ros2`: (domain, type) subscription → ROS topic; `from_ros2`: ROS topic → (its ROS
    type, the event name it is pushed as)."""

    to_ros2: dict[tuple[str, str], str] = field(default_factory=dict)
    from_ros2: dict[str, tuple[str, str]] = field(default_factory=dict)

    def overlap(self) -> set[str]:
        """ROS topics bridged both ways (which would go round in circles)."""
        return set(self.to_ros2.values()) & set(self.from_ros2)


class _ToRos2(StructuredPushConsumer):
    """Takes the events of one subscription (reactor thread) and publishes their payloads on
    one ROS 2 topic; the publisher is made with the first event, whose type it takes."""

    def __init__(self, channel: Any, node: Node, topic: str) -> None:
        super().__init__(channel, depth=KEEP_ALL)
        self.node = node
        self.topic = topic
        self.publisher: Publisher[Any] | None = None
        self.sent = 0

    def push_structured_event(self, event: StructuredEvent) -> None:
        payload = event.payload
        if self.publisher is None:
            if not getattr(payload, "_ros2_type", ""):
                _peer_warnings.warning(
                    "%s/%s is no ROS 2 type: not published on %s",
                    event.domain_name, event.type_name, self.topic,
                )  # fmt: skip
                return
            self.publisher = self.node.publisher(type(payload), self.topic)
        if not isinstance(payload, self.publisher.msg_type):
            _peer_warnings.warning(
                "%s/%s is a %s, not the %s published on %s", event.domain_name,
                event.type_name, type(payload).__name__, self.publisher.msg_type.__name__,
                self.topic,
            )  # fmt: skip
            return
        self.publisher.publish(payload)
        self.sent += 1


class Bridge:
    """A running bridge between `channel` (of `server`) and the ROS 2 graph, along `routes`."""

    def __init__(self, server: Any, channel: Any, routes: Routes, node: Node) -> None:
        self.node = node
        registry.discover()  # the generated types on the path: events of any are decoded
        self.to_ros2: list[_ToRos2] = []
        for sub, topic in routes.to_ros2.items():
            consumer = _ToRos2(channel, node, node.resolve(topic))
            consumer.set_subscriptions([sub])
            self.to_ros2.append(consumer)
        self.supplier: StructuredPushSupplier | None = None
        if routes.from_ros2:
            self.supplier = StructuredPushSupplier(channel, server.options.naming_context)
        for topic, (ros_type, event) in routes.from_ros2.items():
            cls = message_class(ros_type)
            if cls is None:
                raise RouteError(
                    f"{topic}: no generated type here for {ros_type} (compile its .msg with "
                    "miro-idl and put it on PYTHONPATH)"
                )
            node.subscription(cls, topic, self._pusher(event))

    def _pusher(self, event: str) -> Any:
        supplier = self.supplier
        assert supplier is not None

        def push(message: Any) -> None:  # on the ROS 2 side's thread: push() takes any
            supplier.push(event, message)

        return push

    def close(self) -> None:
        for consumer in self.to_ros2:
            consumer.close()
        self.node.close()
