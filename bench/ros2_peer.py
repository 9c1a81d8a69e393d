"""The rclpy side of bench/bench_ros2.py, run in the ROS 2 environment of tests/ros2_env.py.

ros2_peer.py recv TOPIC ACKS
    take sensor_msgs/Image messages on TOPIC until one whose encoding is `end`; after each,
    publish on ACKS (std_msgs/UInt64) how many have arrived; print JSON: the count, the
    seconds from the first to the last, the median latency (now - header.stamp)
ros2_peer.py send TOPIC ACKS SIZE SECONDS WINDOW
    publish Images of SIZE data bytes, stamped at sending, for SECONDS, never more than
    WINDOW ahead of the count the receiver acknowledged on ACKS (the same credit window, and
    the same arrangement, as the miro sender of bench_ros2.py); then the `end` message
"""

from __future__ import annotations

import json
import sys
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import UInt64

QUIET = 10.0  # seconds without a message after which the receiver gives up


def receive(node: Node, topic: str, acks: str) -> None:
    lat: list[int] = []
    times: list[float] = []
    done = [False]
    ack_pub = node.create_publisher(UInt64, acks, 10)
    ack = UInt64()

    def on(m: Image) -> None:
        now = time.time_ns()
        if m.encoding == "end":
            done[0] = True
            return
        times.append(time.monotonic())
        lat.append(now - (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec))
        ack.data = len(lat)
        ack_pub.publish(ack)

    node.create_subscription(Image, topic, on, 10)
    print("ready", flush=True)
    started = time.monotonic()
    while not done[0]:
        rclpy.spin_once(node, timeout_sec=0.05)
        last = times[-1] if times else started
        if time.monotonic() - last > QUIET + (30 if not times else 0):
            break
    elapsed = times[-1] - times[0] if len(times) > 1 else 0.0
    lat.sort()
    p50 = lat[len(lat) // 2] / 1000 if lat else None
    print(json.dumps({"count": len(lat), "seconds": elapsed, "p50_us": p50}), flush=True)


def send(node: Node, topic: str, acks: str, size: int, seconds: float, window: int) -> None:
    """As the miro sender: the acks are taken by an executor on a thread of their own (as the
    miro side's delivering thread), the sender waits on a condition for credit."""
    acked = [0]
    moved = threading.Condition()

    def on_ack(m: UInt64) -> None:
        with moved:
            acked[0] = max(acked[0], m.data)
            moved.notify()

    pub = node.create_publisher(Image, topic, 10)
    ack_sub = node.create_subscription(UInt64, acks, on_ack, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    while pub.get_subscription_count() < 1 or ack_sub.get_publisher_count() < 1:
        time.sleep(0.05)
    time.sleep(0.5)  # the receiver matches this writer too
    msg = Image(height=1, width=size, encoding="mono8", step=size, data=bytes(size))
    sent = [0]
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        with moved:
            if not moved.wait_for(lambda: sent[0] - acked[0] < window, QUIET):
                raise SystemExit(f"no ack for {QUIET:g} s after message {sent[0]}")
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        pub.publish(msg)
        sent[0] += 1
    with moved:
        moved.wait_for(lambda: acked[0] >= sent[0], QUIET)
    pub.publish(Image(encoding="end"))
    time.sleep(0.5)  # let the last one go out before the node does
    executor.shutdown()


def main() -> None:
    mode, topic, acks = sys.argv[1], sys.argv[2], sys.argv[3]
    rclpy.init()
    node = Node(f"bench_{mode}")
    if mode == "recv":
        receive(node, topic, acks)
    else:
        send(node, topic, acks, int(sys.argv[4]), float(sys.argv[5]), int(sys.argv[6]))
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
