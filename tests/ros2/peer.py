"""An rclpy node (ROS 2 Kilted, Fast DDS) the ROS 2 runtime tests talk to, in the ROS 2
environment of tests/ros2_env.py. Prints one JSON document on stdout when done.

  peer.py sub TYPE TOPIC COUNT TIMEOUT      take COUNT messages; print them and the graph
  peer.py pub TYPE TOPIC SPEC TIMEOUT       publish SPEC (JSON) at 20 Hz until stdin closes
  peer.py graph NODE TIMEOUT [SERVICE TYPE] wait for node NODE; print the graph (and whether a
                                            client of SERVICE sees it ready)
  peer.py serve TYPE SERVICE TIMEOUT       answer SERVICE (SetBool: success=data, message
                                            "rclpy <n>"; BasicTypes: the request changed as
                                            test_ros2_runtime's miro service changes it) until
                                            stdin closes; print the number of calls
  peer.py call TYPE SERVICE SPECS TIMEOUT   call SERVICE with each request of SPECS (a JSON
                                            list) in turn; print the responses (null: none)
"""

from __future__ import annotations

import importlib
import json
import select
import sys
import time
from typing import Any

import canon
import rclpy
from rclpy.node import Node


def message_class(name: str) -> Any:
    pkg, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), cls)


def fill(msg: Any, spec: dict[str, Any]) -> Any:
    for key, value in spec.items():
        current = getattr(msg, key)
        if isinstance(value, dict):
            fill(current, value)
        else:
            setattr(msg, key, value)
    return msg


def graph(node: Node) -> dict[str, Any]:
    nodes = [f"{ns.rstrip('/')}/{n}" for n, ns in node.get_node_names_and_namespaces()]
    out: dict[str, Any] = {
        "nodes": sorted(nodes),
        "topics": {n: t for n, t in node.get_topic_names_and_types()},
        "services": {n: t for n, t in node.get_service_names_and_types()},
        "by_node": {},
    }
    for name, ns in node.get_node_names_and_namespaces():
        try:
            pubs = node.get_publisher_names_and_types_by_node(name, ns)
            subs = node.get_subscriber_names_and_types_by_node(name, ns)
            srvs = node.get_service_names_and_types_by_node(name, ns)
        except Exception as e:  # a node that went meanwhile
            out["by_node"][name] = str(e)
            continue
        out["by_node"][name] = {
            "publishers": {n: t for n, t in pubs},
            "subscribers": {n: t for n, t in subs},
            "services": {n: t for n, t in srvs},
        }
    return out


def main() -> None:
    mode = sys.argv[1]
    rclpy.init()
    node = Node("rclpy_peer")
    result: dict[str, Any] = {}
    if mode == "sub":
        cls, topic = sys.argv[2], sys.argv[3]
        count, timeout = int(sys.argv[4]), float(sys.argv[5])
        got: list[Any] = []
        node.create_subscription(
            message_class(cls), topic, lambda m: got.append(canon.canon(m)), 10
        )
        deadline = time.monotonic() + timeout
        while len(got) < count and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        result = {"received": got, "graph": graph(node)}
    elif mode == "pub":
        cls, topic, spec, timeout = sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5])
        msg = fill(message_class(cls)(), canon.expand(json.loads(spec)))
        pub = node.create_publisher(message_class(cls), topic, 10)
        deadline = time.monotonic() + timeout
        sent = 0
        while time.monotonic() < deadline:
            pub.publish(msg)
            sent += 1
            rclpy.spin_once(node, timeout_sec=0.05)
            if select.select([sys.stdin], [], [], 0)[0] and not sys.stdin.readline():
                break
        result = {"sent": sent}
    elif mode == "graph":
        want, timeout = sys.argv[2], float(sys.argv[3])
        deadline = time.monotonic() + timeout
        client = None
        if len(sys.argv) > 5:
            client = node.create_client(message_class(sys.argv[5]), sys.argv[4])
        while time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
            if want in graph(node)["nodes"] and (client is None or client.service_is_ready()):
                time.sleep(0.5)  # let the endpoints of the node arrive too
                rclpy.spin_once(node, timeout_sec=0.1)
                break
        result = {"graph": graph(node), "service_ready": bool(client and client.service_is_ready())}
    elif mode == "serve":
        cls, service, timeout = sys.argv[2], sys.argv[3], float(sys.argv[4])
        calls = [0]

        def answer(request: Any, response: Any) -> Any:
            calls[0] += 1
            if hasattr(request, "data"):  # std_srvs/SetBool
                response.success = request.data
                response.message = f"rclpy {calls[0]}"
                return response
            response.bool_value = not request.bool_value
            response.float64_value = request.float64_value * 2
            response.int8_value = -request.int8_value
            response.uint16_value = request.uint16_value + 1
            response.int64_value = request.int64_value - 1
            response.uint64_value = request.uint64_value // 2
            response.string_value = request.string_value.upper()
            return response

        node.create_service(message_class(cls), service, answer)
        print("ready", flush=True)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
            if select.select([sys.stdin], [], [], 0)[0] and not sys.stdin.readline():
                break
        result = {"calls": calls[0]}
    elif mode == "call":
        cls, service, specs, timeout = sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5])
        client = node.create_client(message_class(cls), service)
        deadline = time.monotonic() + timeout
        ready = client.wait_for_service(timeout_sec=timeout)
        responses: list[Any] = []
        for spec in json.loads(specs) if ready else []:
            left = deadline - time.monotonic()
            if left <= 0:  # (a negative timeout would wait for ever)
                responses.append(None)
                continue
            request = fill(message_class(cls).Request(), canon.expand(spec))
            future = client.call_async(request)
            rclpy.spin_until_future_complete(node, future, timeout_sec=left)
            responses.append(canon.canon(future.result()) if future.done() else None)
        result = {"ready": ready, "responses": responses}
    node.destroy_node()
    rclpy.shutdown()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
