"""`miro bridge ros2` (miro_gen/bridges/ros2.py) between a miro-gen event channel and real rclpy
nodes (ROS 2 Kilted, Fast DDS, tests/ros2/peer.py): a supplier's Twist events reach an rclpy
subscriber, an rclpy publisher's Strings reach a miro consumer as events, and rclpy's graph
lists the bridge's node. Loopback only, as tests/ros2/test_ros2_runtime.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import test_ros2_runtime as runtime
import zmq
from loopback import NamingProcess
from test_ros2_runtime import ROS2, _cls, _peer, _result

from miro_gen import Server
from miro_gen.transport.events import (
    EventChannelFactory,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)

pytest.importorskip("cyclonedds")
pytestmark = pytest.mark.skipif(ROS2 is None, reason="no ROS 2 environment")

ros_types = runtime.ros_types  # the fixtures: the ROS 2 interfaces compiled, a domain
domain = runtime.domain


def test_bridge_relays_between_a_miro_channel_and_rclpy_nodes(ros_types: Path, domain: int) -> None:
    Twist, Vector3 = _cls("geometry_msgs/msg/Twist"), _cls("geometry_msgs/msg/Vector3")
    naming = NamingProcess()
    server = Server(["test", "--naming", naming.endpoint, "-MNC", "robot"], context=zmq.Context())
    channel = EventChannelFactory(server).create_channel("EventChannel")
    received: list[StructuredEvent] = []
    arrived = threading.Event()

    class Chatter(StructuredPushConsumer):
        def push_structured_event(self, event: StructuredEvent) -> None:
            received.append(event)
            if len(received) >= 3:
                arrived.set()

    Chatter(channel).set_subscriptions([("bridge", "Chatter")])
    supplier = StructuredPushSupplier(channel)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ros_types), *sys.path]))
    bridge = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "bridge", "ros2", "--naming",
         naming.endpoint, "-MNC", "bridge", "--channel", "robot/EventChannel",
         "--to-ros2", "*/Twist=/miro_twist",
         "--from-ros2", "/rclpy_out:std_msgs/msg/String=Chatter"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        assert bridge.stdout is not None
        line = bridge.stdout.readline()
        assert line.startswith("bridging"), line + (bridge.stderr.read() if bridge.stderr else "")
        # miro → ROS 2: Twist events until the rclpy subscriber has three
        sub = _peer(domain, "sub", "geometry_msgs/msg/Twist", "/miro_twist", "3", "90")
        twist = Twist(linear=Vector3(x=1.5, y=-2.0), angular=Vector3(z=0.25))
        stop = threading.Event()
        while sub.poll() is None and not stop.wait(0.05):
            supplier.push("Twist", twist)
        result = _result(sub)
        assert len(result["received"]) == 3
        assert all(r["linear"] == {"x": 1.5, "y": -2.0, "z": 0.0} for r in result["received"])
        assert all(r["angular"]["z"] == 0.25 for r in result["received"])
        assert "/miro_bridge" in result["graph"]["nodes"]
        assert result["graph"]["topics"]["/miro_twist"] == ["geometry_msgs/msg/Twist"]
        # ROS 2 → miro: an rclpy publisher's Strings as Chatter events of the bridge's domain
        pub = _peer(domain, "pub", "std_msgs/msg/String", "/rclpy_out",
                    json.dumps({"data": "from rclpy"}), "90", stdin=subprocess.PIPE)  # fmt: skip
        arrived.wait(90)
        _result(pub)
        assert len(received) >= 3
        assert all((e.domain_name, e.type_name) == ("bridge", "Chatter") for e in received)
        assert all(e.payload.data == "from rclpy" for e in received)
    finally:
        bridge.terminate()
        bridge.communicate(timeout=30)
        server.shutdown()
        thread.join(10)
        naming.stop()


def test_bridge_refuses_circles_and_unknown_types(ros_types: Path) -> None:
    circle = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "bridge", "ros2",
         "--to-ros2", "*/String=/chat", "--from-ros2", "/chat:std_msgs/msg/String"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert circle.returncode == 2
    assert "/chat both ways" in circle.stderr and "Traceback" not in circle.stderr
    bad = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "bridge", "ros2", "--from-ros2", "/chat"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert bad.returncode == 2 and "/TOPIC:pkg/msg/Type" in bad.stderr
