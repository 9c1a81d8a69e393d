"""ROS 2 topics: messages/s and median one-way latency into an rclpy subscriber (ROS 2 Kilted,
Fast DDS), from a miro publisher (miro_gen/ros2, cyclonedds) and from an rclpy publisher, in
the same run, interleaved; sensor_msgs/Image of 16 bytes and of 1 MiB. Loopback only
(`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, a domain of its own).

The receiver stamps nothing: the sender puts its wall-clock time in `header.stamp` as it
publishes, the receiver subtracts it from its own (one machine, one clock). Publishers send as
fast as they go for `--seconds`; keep-last 10 reliable, so a slow receiver costs the sender.
Needs the ROS 2 environment of tests/ros2_env.py (made if missing) and the generated
sensor_msgs types (compiled here from its `share/`).

    python bench/bench_ros2.py [--seconds 3] [--repeats 5]

Not finished: in its first runs the rclpy receiver of a flood from the miro publisher never
printed its count (and ignored SIGTERM); no figures are taken from it yet.
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
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
import ros2_env  # noqa: E402

PEER = Path(__file__).resolve().parent / "ros2_peer.py"
SIZES = {"16 B": 16, "1 MiB": 1 << 20}


def _peer(env: ros2_env.Ros2Env, domain: int, *args: str) -> subprocess.Popen[str]:
    e = env.environ()
    e.update(ROS_DOMAIN_ID=str(domain), RMW_IMPLEMENTATION="rmw_fastrtps_cpp")
    return subprocess.Popen([str(env.python), str(PEER), *args], env=e, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)  # fmt: skip


def _miro_send(image: Any, size: int, seconds: float) -> None:
    from miro_gen.ros2.node import Node

    with Node("bench_miro_send") as node:
        pub = node.publisher(image, "bench")
        pub.wait_for_subscribers(1, 60)
        time.sleep(0.5)
        msg = image(height=1, width=size, encoding="mono8", step=size, data=bytes(size))
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            pub.publish(msg)
        time.sleep(0.5)


def run_once(
    env: ros2_env.Ros2Env, image: Any, sender: str, size: int, seconds: float
) -> dict[str, Any]:
    domain = random.randint(120, 230)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    recv = _peer(env, domain, "recv", "/bench", str(seconds))
    assert recv.stdout is not None and recv.stdout.readline().strip() == "ready"
    if sender == "miro":
        _miro_send(image, size, seconds + 0.5)
    else:
        send = _peer(env, domain, "send", "/bench", str(size), str(seconds + 0.5))
        send.wait(timeout=180)
    out, _ = recv.communicate(timeout=180)
    r = json.loads(out.strip().splitlines()[-1])
    return {"rate": r["count"] / r["seconds"] if r["seconds"] else 0.0, "p50_us": r["p50_us"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--repeats", type=int, default=5)
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

    results: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for _ in range(args.repeats):
        for label, size in SIZES.items():
            for sender in ("miro", "rclpy"):
                results.setdefault((label, sender), []).append(
                    run_once(env, Image, sender, size, args.seconds)
                )
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    head = f"{'message':8} {'sender':6} {'msgs/s median (min-max)':>28}"
    print(head + f" {'p50 latency us median (min-max)':>34}")
    for (label, sender), rows in results.items():
        rates = [r["rate"] for r in rows]
        lats = [r["p50_us"] for r in rows if r["p50_us"] is not None]
        rate = f"{statistics.median(rates):12.0f} ({min(rates):.0f}-{max(rates):.0f})"
        lat = f"{statistics.median(lats):14.0f} ({min(lats):.0f}-{max(lats):.0f})"
        print(f"{label:8} {sender:6} {rate} {lat}")
    for label in SIZES:
        m = statistics.median(r["rate"] for r in results[(label, "miro")])
        r_ = statistics.median(r["rate"] for r in results[(label, "rclpy")])
        ml = statistics.median(r["p50_us"] for r in results[(label, "miro")])
        rl = statistics.median(r["p50_us"] for r in results[(label, "rclpy")])
        print(f"{label}: miro/rclpy rate {m / r_:.2f}x, latency {ml / rl:.2f}x")


if __name__ == "__main__":
    main()
