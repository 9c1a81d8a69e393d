"""rosbag2 files (miro_gen/ros2/bag.py, bag_io.py; `miro log record --ros2`, `miro log
info/echo/play` of rosbag2 files) against readers and peers no one here wrote:

- ROS 2 topics an rclpy node publishes (ROS 2 Kilted, Fast DDS), recorded by miro into a
  rosbag2 MCAP file, read back by rosbags (its AnyReader, types from the file's own `ros2msg`
  definitions) and by mcap-ros2-support's decoder, with the right types and values;
- `miro log record --ros2` in its own process, `miro log info` and `miro log echo` of its file;
- a rosbag2 folder written by rosbags played by `miro log play` to an rclpy subscriber.

No rosbag2 wheel exists (ros2 bag itself cannot be installed without ROS), so rosbags and
mcap-ros2-support stand for it. Loopback only, as tests/ros2/test_ros2_runtime.py.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest
import test_ros2_runtime as runtime
from test_ros2_runtime import CASES, ROS2, _cls, _message, _peer, _result, canon

ros_types = runtime.ros_types  # the fixtures: the ROS 2 interfaces compiled, a domain
domain = runtime.domain

pytest.importorskip("cyclonedds")
pytestmark = pytest.mark.skipif(ROS2 is None, reason="no ROS 2 environment")

RECORDED = [c for c in CASES if c[0].rsplit("/", 1)[1] in ("String", "LaserScan", "Image")]


def _plain(value: Any) -> Any:
    """A message as rosbags or mcap-ros2-support decode it, as canon compares values."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if hasattr(value, "__dataclass_fields__") or hasattr(value, "__slots__"):
        fields = getattr(value, "__dataclass_fields__", None) or value.__slots__
        return {k: _plain(getattr(value, k)) for k in fields if not k.startswith("_")}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _env(ros_types: Path) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(ros_types), *sys.path]))


def _rosbags(path: Path) -> list[tuple[str, str, Any]]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        return [
            (c.topic, c.msgtype, reader.deserialize(raw, c.msgtype))
            for c, _, raw in reader.messages()
        ]


@pytest.mark.parametrize(("type_name", "spec"), RECORDED, ids=[c[0] for c in RECORDED])
def test_rclpy_topic_recorded_by_miro_reads_in_rosbags_and_mcap_ros2(
    ros_types: Path, domain: int, tmp_path: Path, type_name: str, spec: dict[str, Any]
) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from miro_gen.ros2.bag import BagWriter
    from miro_gen.ros2.bag_io import BagRecorder
    from miro_gen.ros2.node import Node

    path = tmp_path / "rclpy.mcap"
    writer = BagWriter(str(path))
    enough = threading.Event()
    with Node("miro_bag") as node:
        recorder = BagRecorder(node, writer, ["/rclpy_out"])
        peer = _peer(domain, "pub", type_name, "/rclpy_out", json.dumps(spec), "90",
                     stdin=subprocess.PIPE)  # fmt: skip
        while not enough.wait(0.05) and peer.poll() is None:
            recorder.poll()
            if writer.messages >= 3:
                enough.set()
        _result(peer)  # closing its stdin stops it
        node.context.dispatcher.drain()
    writer.finish()
    assert recorder.recording == {"/rclpy_out": type_name}
    want = canon.canon(_message(type_name, spec))
    got = _rosbags(path)
    assert len(got) == writer.messages >= 3
    assert {(t, m) for t, m, _ in got} == {("/rclpy_out", type_name)}
    assert all(canon.canon(_plain(v)) == want for _, _, v in got)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages())
    assert [s.name for s, _, _, _ in decoded] == [type_name] * len(got)
    assert all(canon.canon(_plain(d)) == want for _, _, _, d in decoded)
    cls = _cls(type_name)
    assert decoded[0][1].metadata["topic_type_hash"] == cls._ros2_type_hash


def test_miro_log_record_ros2_then_info_and_echo(
    ros_types: Path, domain: int, tmp_path: Path
) -> None:
    from miro_gen.ros2.node import Node

    out = tmp_path / "chatter.mcap"
    env = _env(ros_types)
    rec = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "log", "record", "--ros2", "/chatter",
         "-o", str(out)],
        env=env, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert rec.stderr is not None and "recording /chatter" in rec.stderr.readline()
        String = _cls("std_msgs/msg/String")
        with Node("miro_talker") as node:
            pub = node.publisher(String, "/chatter")
            assert pub.wait_for_subscribers(1, 60)
            for i in range(5):
                pub.publish(String(data=f"hello {i}"))
            assert pub.wait_for_acks(60)
    finally:
        rec.send_signal(signal.SIGINT)
        _, err = rec.communicate(timeout=60)
    assert rec.returncode == 0, err
    got = _rosbags(out)
    assert [(t, m, v.data) for t, m, v in got] == [
        ("/chatter", "std_msgs/msg/String", f"hello {i}") for i in range(5)
    ]
    info = subprocess.run([sys.executable, "-m", "miro_gen.cli.main", "log", "info", str(out)],
                          env=env, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert info.returncode == 0, info.stderr
    line = next(x for x in info.stdout.splitlines() if x.strip().startswith("/chatter"))
    assert "std_msgs/msg/String" in line and " 5 events" in line
    echo = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "log", "echo", str(out), "/chatter"],
        env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert echo.returncode == 0, echo.stderr
    assert [x.split(" ", 2)[2] for x in echo.stdout.splitlines()] == [
        f"#{i + 1} String(data='hello {i}')" for i in range(5)
    ]


def test_miro_log_record_ros2_duration_finishes_the_bag_by_itself(
    ros_types: Path, domain: int, tmp_path: Path
) -> None:
    out = tmp_path / "quiet.mcap"
    rec = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "log", "record", "--ros2", "/nobody",
         "--duration", "0.5", "-o", str(out)],
        env=_env(ros_types), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert rec.returncode == 0, rec.stderr
    assert f"{out}: 0 messages in" in rec.stderr
    assert _rosbags(out) == []


def test_rosbags_written_bag_plays_through_miro_log_play_to_rclpy(
    ros_types: Path, domain: int, tmp_path: Path
) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    Twist = store.types["geometry_msgs/msg/Twist"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=store)
        for i in range(5):
            msg = Twist(linear=Vector3(x=float(i), y=0.5, z=0.0),
                        angular=Vector3(x=0.0, y=0.0, z=-1.25))  # fmt: skip
            writer.write(
                conn, 1_000_000_000 + i * 10_000_000, store.serialize_cdr(msg, Twist.__msgtype__)
            )
    peer = _peer(domain, "sub", "geometry_msgs/msg/Twist", "/cmd_vel", "3", "90")
    play = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "log", "play", "--loop", "--wait", "0",
         str(bag)],
        env=_env(ros_types), stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        result = _result(peer)
    finally:
        play.send_signal(signal.SIGINT)
        _, err = play.communicate(timeout=60)
    assert play.returncode == 0, err
    got = result["received"]
    assert len(got) == 3
    xs = [r["linear"]["x"] for r in got]
    assert set(xs) <= {0.0, 1.0, 2.0, 3.0, 4.0}
    assert all(r["linear"]["y"] == 0.5 and r["angular"]["z"] == -1.25 for r in got)
    assert "/cmd_vel" in result["graph"]["topics"]
