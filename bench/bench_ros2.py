"""ROS 2 topics: messages/s and median one-way latency into an rclpy subscriber (ROS 2 Kilted,
Fast DDS), from a miro publisher (miro_gen/ros2, cyclonedds) and from an rclpy publisher, in
the same run, interleaved; sensor_msgs/Image with 16 bytes of data (a 64-byte CDR message) and
with 1 MiB. Loopback only (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, a domain per run).

Both senders are paced the same way, by a credit window: the rclpy receiver publishes on a
reply topic (std_msgs/UInt64) how many messages it has taken, after each one, and a sender
never has more than WINDOW messages ahead of that count. So neither sender can flood the
receiver (an unbounded one stalled it: keep-last 10 drops, then Fast DDS's repair traffic),
and neither waits on DDS acks (rclpy's `wait_for_all_acked` made its sender crawl at ~2 msg/s).
What is measured is how fast a sender can feed the receiver through that window, and the
latency the messages see there: the receiver subtracts `header.stamp` (the sender's clock
at publishing) from its own at arrival (one machine, one clock). The rate is the receiver's,
first to last message of a run; each run sends for SECONDS. Needs the ROS 2 environment of
tests/ros2_env.py (made if missing); the types are compiled here from its `share/`.

    python bench/bench_ros2.py [--repeats 5] [--seconds 2.5] [--window 8]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
import ros2_env  # noqa: E402

PEER = Path(__file__).resolve().parent / "ros2_peer.py"
SIZES = {"16 B": 16, "1 MiB": 1 << 20}
WINDOW = 8  # messages a sender may be ahead of the receiver's count (< keep-last 10)
QUIET = 10.0  # seconds without an ack after which a sender gives up


def _peer(env: ros2_env.Ros2Env, domain: int, *args: str) -> subprocess.Popen[str]:
    e = env.environ()
    e.update(ROS_DOMAIN_ID=str(domain), RMW_IMPLEMENTATION="rmw_fastrtps_cpp")
    return subprocess.Popen([str(env.python), str(PEER), *args], env=e, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)  # fmt: skip


def _miro_send(types: Any, size: int, seconds: float, window: int) -> None:
    """The miro sender: the same credit window as ros2_peer.py's rclpy sender."""
    from miro_gen.ros2.node import Node

    image, uint64 = types
    acked = [0]
    moved = threading.Condition()

    def on_ack(m: Any) -> None:
        with moved:
            acked[0] = max(acked[0], m.data)
            moved.notify()

    with Node("bench_miro_send") as node:
        pub = node.publisher(image, "bench")
        acks = node.subscription(uint64, "bench_acks", on_ack)
        pub.wait_for_subscribers(1, 60)
        acks.wait_for_publishers(1, 60)
        time.sleep(0.5)  # the receiver matches this writer too
        msg = image(height=1, width=size, encoding="mono8", step=size, data=bytes(size))
        sent = [0]
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            with moved:
                if not moved.wait_for(lambda: sent[0] - acked[0] < window, QUIET):
                    raise SystemExit(f"no ack for {QUIET:g} s after message {sent[0]}")
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            pub.publish(msg)
            sent[0] += 1
        with moved:
            moved.wait_for(lambda: acked[0] >= sent[0], QUIET)
        pub.publish(image(encoding="end"))
        pub.wait_for_acks(QUIET)


def run_once(
    env: ros2_env.Ros2Env, types: Any, sender: str, size: int, seconds: float, window: int
) -> dict[str, Any]:
    domain = random.randint(120, 230)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    recv = _peer(env, domain, "recv", "/bench", "/bench_acks")
    assert recv.stdout is not None and recv.stdout.readline().strip() == "ready"
    if sender == "miro":
        _miro_send(types, size, seconds, window)
    else:
        send = _peer(env, domain, "send", "/bench", "/bench_acks", str(size), str(seconds),
                     str(window))  # fmt: skip
        send.wait(timeout=300)
    out, _ = recv.communicate(timeout=300)
    r = json.loads(out.strip().splitlines()[-1])
    rate = (r["count"] - 1) / r["seconds"] if r["seconds"] else 0.0
    return {"rate": rate, "p50_us": r["p50_us"], "count": r["count"]}


def _spread(values: list[float], fmt: str) -> str:
    return f"{statistics.median(values):{fmt}} ({min(values):.0f}-{max(values):.0f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=2.5, help="seconds each sender sends")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--window", type=int, default=WINDOW, help="the senders' credit window")
    args = ap.parse_args()
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("CYCLONEDDS_URI", None)
    env = ros2_env.make()
    gen = Path(tempfile.mkdtemp(prefix="bench_ros2_"))
    share = env.share
    files = [str(p) for pkg in ("builtin_interfaces", "std_msgs", "sensor_msgs")
             for p in sorted((share / pkg / "msg").glob("*.msg"))]  # fmt: skip
    subprocess.run([sys.executable, "-m", "miro_gen.cli.idl", "-I", str(share), "-o", str(gen),
                    *files], check=True, capture_output=True)  # fmt: skip
    sys.path.insert(0, str(gen))
    from sensor_msgs.msg import Image
    from std_msgs.msg import UInt64

    load_before = os.getloadavg()
    results: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for _ in range(args.repeats):
        for label, size in SIZES.items():
            for sender in ("miro", "rclpy"):
                results.setdefault((label, sender), []).append(
                    run_once(env, (Image, UInt64), sender, size, args.seconds, args.window)
                )
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"load average: {' '.join(f'{x:.2f}' for x in load_before)} before, {load} after")
    print(f"credit window {args.window}, {args.seconds:g} s sent per run, "
          f"{args.repeats} interleaved repeats; median (min-max)")  # fmt: skip
    print(f"{'data':6} {'sender':6} {'received msgs/s':>22} {'p50 latency us':>22}  received")
    for (label, sender), rows in results.items():
        rate = _spread([r["rate"] for r in rows], "10.0f")
        lat = _spread([r["p50_us"] for r in rows if r["p50_us"] is not None], "10.0f")
        got = f"{min(r['count'] for r in rows)}-{max(r['count'] for r in rows)}"
        print(f"{label:6} {sender:6} {rate:>22} {lat:>22}  {got}")
    for label in SIZES:
        m = statistics.median(r["rate"] for r in results[(label, "miro")])
        r_ = statistics.median(r["rate"] for r in results[(label, "rclpy")])
        ml = statistics.median(r["p50_us"] for r in results[(label, "miro")])
        rl = statistics.median(r["p50_us"] for r in results[(label, "rclpy")])
        print(f"{label}: miro/rclpy rate {m / r_:.2f}x, p50 latency {ml / rl:.2f}x")


if __name__ == "__main__":
    main()
