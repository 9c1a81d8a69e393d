"""The ROS 2 side of miro-gen (miro_gen/ros2) against real rclpy nodes: ROS 2 Kilted's wheels
with Fast DDS (rmw_fastrtps_cpp), installed in an environment of their own by tests/ros2_env.py
and run as subprocesses (tests/ros2/peer.py). All on loopback: both sides get
`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` and a domain of their own.

- an rclpy subscriber receives a miro publisher's messages, and a miro subscription an rclpy
  publisher's, for std_msgs, geometry_msgs and sensor_msgs types, a 1 MB Image among them;
- rclpy's graph lists the miro node, its topics (with their types) and its service;
- a miro client calls a miro service in another process over DDS (std_srvs/SetBool and a
  service of this test's own), with rmw_cyclonedds' request header;
- an rclpy client (Fast DDS) calls miro services (std_srvs/SetBool, test_msgs/BasicTypes),
  answered by miro's own RTPS participant (miro_gen/ros2/rtps) with related_sample_identity;
- a miro client calls rclpy services (the same two) through that participant.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import textwrap
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import ros2_env
from miro_cli import run_miro_idl
from repo_paths import TESTS

pytest.importorskip("cyclonedds")

HERE = TESTS
PEER = HERE / "ros2" / "peer.py"
sys.path.insert(0, str(HERE / "ros2"))
import canon  # noqa: E402  (tests/ros2/canon.py, shared with the ROS 2 side)

ROS2, REASON = ros2_env.available()
pytestmark = pytest.mark.skipif(ROS2 is None, reason=REASON or "")

CASES: list[tuple[str, dict[str, Any]]] = [
    ("std_msgs/msg/String", {"data": "hello from miro, ünïcode"}),
    ("std_msgs/msg/Header", {"stamp": {"sec": 1712345678, "nanosec": 123456789},
                             "frame_id": "base"}),
    ("geometry_msgs/msg/Twist", {"linear": {"x": 1.5, "y": -2.25, "z": 0.0},
                                 "angular": {"x": 0.0, "y": 0.0, "z": 0.75}}),
    ("geometry_msgs/msg/PoseWithCovariance", {"pose": {"position": {"x": 1.0, "y": 2.0, "z": 3.0},
                                              "orientation": {"w": 1.0}},
                                              "covariance": [float(i) for i in range(36)]}),
    ("sensor_msgs/msg/LaserScan", {"header": {"frame_id": "laser"}, "angle_min": -1.5,
                                   "angle_max": 1.5, "ranges": [0.5 * i for i in range(181)],
                                   "intensities": [1.0, 2.0]}),
    ("sensor_msgs/msg/Image", {"header": {"stamp": {"sec": 7, "nanosec": 8}, "frame_id": "cam"},
                               "height": 1024, "width": 1024, "encoding": "mono8",
                               "is_bigendian": 0, "step": 1024,
                               "data": {"__pattern__": 1024 * 1024}}),
]  # fmt: skip
IDS = [c[0].rsplit("/", 1)[1] for c in CASES]

OWN_SRV = "int64 a\nint64 b\n---\nint64 sum\nstring note\n"


@pytest.fixture(scope="module")
def ros_types(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The ROS 2 interfaces the tests use, compiled by miro-idl from the wheels' `.msg` and
    `.srv` files (and a service of the tests' own), importable while the module runs."""
    assert ROS2 is not None
    out = tmp_path_factory.mktemp("ros_types")
    own = tmp_path_factory.mktemp("own") / "miro_test_srvs" / "srv"
    own.mkdir(parents=True)
    (own / "AddTwoInts.srv").write_text(OWN_SRV)
    share = ROS2.share
    files = [str(own / "AddTwoInts.srv")]
    for pkg in ("builtin_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "service_msgs"):
        files += sorted(str(p) for p in (share / pkg / "msg").glob("*.msg"))
    files += sorted(str(p) for p in (share / "std_srvs" / "srv").glob("*.srv"))
    files.append(str(share / "test_msgs" / "srv" / "BasicTypes.srv"))
    done = run_miro_idl("-I", str(share), "-I", str(own.parent.parent), "-o", str(out), *files)
    assert done.returncode == 0, done.stderr
    sys.path.insert(0, str(out))
    yield out
    sys.path.remove(str(out))


@pytest.fixture
def domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A ROS domain of the test's own (other runs on this machine use others), on loopback."""
    d = random.randint(120, 230)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(d))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("CYCLONEDDS_URI", raising=False)
    return d


def _peer(domain: int, *args: str, stdin: Any = None) -> subprocess.Popen[str]:
    assert ROS2 is not None
    env = ROS2.environ()
    env.update(ROS_DOMAIN_ID=str(domain), RMW_IMPLEMENTATION="rmw_fastrtps_cpp")
    return subprocess.Popen(
        [str(ROS2.python), str(PEER), *args],
        env=env, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def _result(proc: subprocess.Popen[str], timeout: float = 120) -> Any:
    out, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, err[-3000:]
    return json.loads(out)


def _cls(name: str) -> Any:
    import importlib

    pkg, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), cls)


def _message(name: str, spec: dict[str, Any]) -> Any:
    cls = _cls(name)
    msg = cls()
    _fill(msg, canon.expand(spec))
    return msg


def _fill(msg: Any, spec: dict[str, Any]) -> None:
    for key, value in spec.items():
        if isinstance(value, dict):
            _fill(getattr(msg, key), value)
        else:
            setattr(msg, key, value)


@pytest.mark.parametrize(("type_name", "spec"), CASES, ids=IDS)
def test_rclpy_subscriber_receives_a_miro_publishers_messages(
    ros_types: Path, domain: int, type_name: str, spec: dict[str, Any]
) -> None:
    from miro_gen.ros2.node import Node

    peer = _peer(domain, "sub", type_name, "/miro_out", "3", "90")
    msg = _message(type_name, spec)
    with Node("miro_talker") as node:
        pub = node.publisher(_cls(type_name), "miro_out")
        stop = threading.Event()
        while peer.poll() is None and not stop.wait(0.05):
            pub.publish(msg)
        result = _result(peer)
    assert len(result["received"]) == 3
    assert all(r == canon.canon(msg) for r in result["received"])
    g = result["graph"]
    assert "/miro_talker" in g["nodes"]
    assert g["topics"]["/miro_out"] == [type_name]


@pytest.mark.parametrize(("type_name", "spec"), CASES, ids=IDS)
def test_miro_subscription_receives_an_rclpy_publishers_messages(
    ros_types: Path, domain: int, type_name: str, spec: dict[str, Any]
) -> None:
    from miro_gen.ros2.node import Node

    got: list[Any] = []
    arrived = threading.Event()

    def on_message(m: Any) -> None:
        got.append(m)
        if len(got) >= 3:
            arrived.set()

    with Node("miro_listener") as node:
        node.subscription(_cls(type_name), "/rclpy_out", on_message)
        peer = _peer(domain, "pub", type_name, "/rclpy_out", json.dumps(spec), "90",
                     stdin=subprocess.PIPE)  # fmt: skip
        arrived.wait(90)
        sent = _result(peer)["sent"]  # closing its stdin stops the publisher
    assert len(got) >= 3, f"rclpy sent {sent}, miro took {len(got)}"
    want = canon.canon(_message(type_name, spec))
    assert all(canon.canon(m) == want for m in got)


def test_rclpy_graph_lists_the_miro_node_its_topics_and_its_service(
    ros_types: Path, domain: int
) -> None:
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.services import Service

    SetBool = _cls("std_srvs/srv/SetBool")
    with Node("miro_graph", namespace="/robot") as node:
        node.publisher(_cls("geometry_msgs/msg/Twist"), "cmd_vel")
        node.subscription(_cls("sensor_msgs/msg/LaserScan"), "scan", lambda m: None)
        Service(node, SetBool, "enable", lambda r: _cls("std_srvs/srv/SetBool_Response")())
        result = _result(
            _peer(
                domain, "graph", "/robot/miro_graph", "90", "/robot/enable", "std_srvs/srv/SetBool"
            )
        )
        ours = node.graph.topics()
    g = result["graph"]
    assert "/robot/miro_graph" in g["nodes"]
    assert g["topics"]["/robot/cmd_vel"] == ["geometry_msgs/msg/Twist"]
    assert g["topics"]["/robot/scan"] == ["sensor_msgs/msg/LaserScan"]
    assert g["services"]["/robot/enable"] == ["std_srvs/srv/SetBool"]
    by_node = g["by_node"]["miro_graph"]
    assert by_node["publishers"] == {"/robot/cmd_vel": ["geometry_msgs/msg/Twist"]}
    assert by_node["subscribers"] == {"/robot/scan": ["sensor_msgs/msg/LaserScan"]}
    assert by_node["services"] == {"/robot/enable": ["std_srvs/srv/SetBool"]}
    # rclpy's client sees the miro service ready (its request reader and reply writer).
    assert result["service_ready"] is True
    # and the miro side's own view of the graph agrees
    assert ours["/robot/cmd_vel"] == ["geometry_msgs/msg/Twist"]


SERVER = textwrap.dedent(
    """
    import sys, threading
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.services import Service
    from std_srvs.srv import SetBool, SetBool_Response
    from miro_test_srvs.srv import AddTwoInts, AddTwoInts_Response
    node = Node("miro_server")
    Service(node, SetBool, "enable",
            lambda r: SetBool_Response(success=r.data, message=f"set to {r.data}"))
    Service(node, AddTwoInts, "add",
            lambda r: AddTwoInts_Response(sum=r.a + r.b, note=f"{r.a}+{r.b}"))
    print("ready", flush=True)
    sys.stdin.read()
    node.close()
    """
)


def test_miro_client_calls_a_miro_service_in_another_process_over_dds(
    ros_types: Path, domain: int
) -> None:
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.services import Client

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ros_types), *sys.path]))
    server = subprocess.Popen([sys.executable, "-c", SERVER], env=env, text=True,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE)  # fmt: skip
    try:
        assert server.stdout is not None and server.stdout.readline().strip() == "ready"
        with Node("miro_caller") as node:
            enable = Client(node, _cls("std_srvs/srv/SetBool"), "enable")
            add = Client(node, _cls("miro_test_srvs/srv/AddTwoInts"), "/add")
            assert enable.wait_for_service(60) and add.wait_for_service(60)
            on = enable.call(_cls("std_srvs/srv/SetBool_Request")(data=True), timeout=30)
            assert (on.success, on.message) == (True, "set to True")
            Req = _cls("miro_test_srvs/srv/AddTwoInts_Request")
            results = [add.call(Req(a=i, b=-3 * i), timeout=30) for i in range(20)]
            assert [(r.sum, r.note) for r in results] == [
                (-2 * i, f"{i}+{-3 * i}") for i in range(20)
            ]
    finally:
        assert server.stdin is not None
        server.stdin.close()
        server.wait(timeout=30)


def _basic_reply(r: Any) -> Any:
    """test_msgs/BasicTypes: each value changed so that an echo would not pass."""
    out = _cls("test_msgs/srv/BasicTypes_Response")()
    out.bool_value = not r.bool_value
    out.float64_value = r.float64_value * 2
    out.int8_value = -r.int8_value
    out.uint16_value = r.uint16_value + 1
    out.int64_value = r.int64_value - 1
    out.uint64_value = r.uint64_value // 2
    out.string_value = r.string_value.upper()
    return out


def test_rclpy_client_on_fast_dds_calls_miro_services(ros_types: Path, domain: int) -> None:
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.services import Service

    SetBool, Response = _cls("std_srvs/srv/SetBool"), _cls("std_srvs/srv/SetBool_Response")
    calls: list[bool] = []

    def enable(r: Any) -> Any:
        calls.append(r.data)
        return Response(success=r.data, message=f"set to {r.data} ({len(calls)})")

    basic = [{"bool_value": i % 2 == 0, "float64_value": 0.5 * i, "int8_value": -i,
              "uint16_value": 1000 + i, "int64_value": -(2**40) * i, "uint64_value": 2**63 + i,
              "string_value": f"call {i}, ünïcode"} for i in range(5)]  # fmt: skip
    with Node("miro_server", namespace="/robot") as node:
        Service(node, SetBool, "enable", enable)
        Service(node, _cls("test_msgs/srv/BasicTypes"), "/basic", _basic_reply)
        on_off = [{"data": i % 3 != 0} for i in range(10)]
        first = _peer(domain, "call", "std_srvs/srv/SetBool", "/robot/enable",
                      json.dumps(on_off), "90")  # fmt: skip
        second = _peer(domain, "call", "test_msgs/srv/BasicTypes", "/basic",
                       json.dumps(basic), "90")  # fmt: skip
        got, got_basic = _result(first), _result(second)
    assert got["ready"] is True
    # each reply went to its own request: the n-th call saw the n-th answer
    assert got["responses"] == [
        {"success": s["data"], "message": f"set to {s['data']} ({i + 1})"}
        for i, s in enumerate(on_off)
    ]
    assert calls == [s["data"] for s in on_off]  # one call each, none answered twice
    assert got_basic["ready"] is True
    for spec, reply in zip(basic, got_basic["responses"], strict=True):
        assert reply is not None
        assert reply["bool_value"] is (not spec["bool_value"])
        assert reply["float64_value"] == spec["float64_value"] * 2
        assert reply["int8_value"] == -spec["int8_value"]
        assert reply["uint16_value"] == spec["uint16_value"] + 1
        assert reply["int64_value"] == spec["int64_value"] - 1
        assert reply["uint64_value"] == spec["uint64_value"] // 2
        assert reply["string_value"] == spec["string_value"].upper()


def test_miro_client_calls_rclpy_services_on_fast_dds(ros_types: Path, domain: int) -> None:
    from miro_gen.ros2.node import Node
    from miro_gen.ros2.services import Client

    enable = _peer(domain, "serve", "std_srvs/srv/SetBool", "/robot/enable", "120",
                   stdin=subprocess.PIPE)  # fmt: skip
    basic = _peer(domain, "serve", "test_msgs/srv/BasicTypes", "/basic", "120",
                  stdin=subprocess.PIPE)  # fmt: skip
    try:
        for peer in (enable, basic):
            assert peer.stdout is not None and peer.stdout.readline().strip() == "ready"
        with Node("miro_caller", namespace="/robot") as node:
            SetBool = _cls("std_srvs/srv/SetBool_Request")
            on = Client(node, _cls("std_srvs/srv/SetBool"), "enable")
            types = Client(node, _cls("test_msgs/srv/BasicTypes"), "/basic")
            assert on.wait_for_service(60) and types.wait_for_service(60)
            replies = [on.call(SetBool(data=i % 2 == 0), timeout=30) for i in range(10)]
            assert [(r.success, r.message) for r in replies] == [
                (i % 2 == 0, f"rclpy {i + 1}") for i in range(10)
            ]
            Req = _cls("test_msgs/srv/BasicTypes_Request")
            for i in range(5):
                req = Req(bool_value=i % 2 == 0, float64_value=0.5 * i, int8_value=-i,
                          uint16_value=1000 + i, int64_value=-(2**40) * i,
                          uint64_value=2**63 + i, string_value=f"call {i}, ünïcode")  # fmt: skip
                want = _basic_reply(req)
                got = types.call(req, timeout=30)
                assert canon.canon(got) == canon.canon(want)
    finally:
        for peer in (enable, basic):
            assert peer.stdin is not None
            peer.stdin.close()
    done = []
    for peer in (enable, basic):
        assert peer.stdout is not None and peer.stderr is not None
        out, err = peer.stdout.read(), peer.stderr.read()
        assert peer.wait(timeout=60) == 0, err[-3000:]
        done.append(json.loads(out)["calls"])
    assert done == [10, 5]  # each call answered once
