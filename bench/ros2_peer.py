"""The rclpy side of bench/bench_ros2.py, run in the ROS 2 environment of tests/ros2_env.py.

ros2_peer.py recv TOPIC COUNT      take COUNT sensor_msgs/Image messages (or stop 3 s after
                                   the last), their latencies (now - header.stamp); print JSON
ros2_peer.py send TOPIC SIZE COUNT publish COUNT Images of SIZE data bytes, stamped at sending,
                                   waiting for every subscriber's acks after each WINDOW: the
                                   sender is bounded, so that it never floods the receiver
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import Image

WINDOW = 5  # messages sent between waits for the subscribers' acks


def main() -> None:
    mode, topic = sys.argv[1], sys.argv[2]
    rclpy.init()
    node = Node(f"bench_{mode}")
    if mode == "recv":
        count = int(sys.argv[3])
        lat: list[int] = []
        times: list[float] = []

        def on(m: Image) -> None:
            now = time.time_ns()
            times.append(time.monotonic())
            lat.append(now - (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec))

        node.create_subscription(Image, topic, on, 10)
        print("ready", flush=True)
        deadline = time.monotonic() + 300
        while len(lat) < count and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
            if times and time.monotonic() - times[-1] > 3.0:
                break
        elapsed = times[-1] - times[0] if len(times) > 1 else 0.0
        lat.sort()
        p50 = lat[len(lat) // 2] / 1000 if lat else None
        print(json.dumps({"count": len(lat), "seconds": elapsed, "p50_us": p50}), flush=True)
    else:
        size, count = int(sys.argv[3]), int(sys.argv[4])
        pub = node.create_publisher(Image, topic, 10)
        msg = Image(height=1, width=size, encoding="mono8", step=size, data=bytes(size))
        while pub.get_subscription_count() < 1:
            rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(0.5)
        for i in range(count):
            now = time.time_ns()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
            pub.publish(msg)
            if WINDOW and i % WINDOW == WINDOW - 1:
                pub.wait_for_all_acked(Duration(seconds=30))
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
