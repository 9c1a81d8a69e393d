"""The rclpy side of bench/bench_ros2.py, run in the ROS 2 environment of tests/ros2_env.py.

ros2_peer.py recv TOPIC SECONDS_AFTER_FIRST   count sensor_msgs/Image messages and their
                                              latencies (now - header.stamp); print JSON
ros2_peer.py send TOPIC SIZE SECONDS          publish Images of SIZE data bytes, stamped
                                              at sending, as fast as rclpy goes
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Image


def main() -> None:
    mode, topic = sys.argv[1], sys.argv[2]
    rclpy.init()
    node = Node(f"bench_{mode}")
    if mode == "recv":
        seconds = float(sys.argv[3])
        lat: list[int] = []
        first = [0.0]

        def on(m: Image) -> None:
            now = time.time_ns()
            if not first[0]:
                first[0] = time.monotonic()
            lat.append(now - (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec))

        node.create_subscription(Image, topic, on, 10)
        print("ready", flush=True)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.01)
            if first[0] and time.monotonic() - first[0] > seconds:
                break
        elapsed = time.monotonic() - first[0] if first[0] else 0.0
        lat.sort()
        print(json.dumps({"count": len(lat), "seconds": elapsed,
                          "p50_us": lat[len(lat) // 2] / 1000 if lat else None}))  # fmt: skip
    else:
        size, seconds = int(sys.argv[3]), float(sys.argv[4])
        pub = node.create_publisher(Image, topic, 10)
        msg = Image(height=1, width=size, encoding="mono8", step=size, data=bytes(size))
        while pub.get_subscription_count() < 1:
            rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(0.5)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            now = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
            pub.publish(msg)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
