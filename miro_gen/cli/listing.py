"""`miro list`: the running services of a robot, from the naming service and their service
objects: the objects each serves (with the operations of their interfaces), the events it
publishes and subscribes to, and its parameter sets; then the event channels, and the names no
miro-gen service accounts for."""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.live_ros2 import add_ros2_flag, wants_ros2
from miro_gen.cli.liveargs import connect
from miro_gen.launch.console import duration_text
from miro_gen.live.remote import LiveError, Robot, Running
from miro_gen.live.show import signatures


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro list",
        description="List the running services: their objects and operations, the events "
        "they publish and subscribe to, their parameter sets; then the event channels and the "
        "other names bound. Accepts the common options (--naming tcp://HOST:PORT).",
    )
    p.add_argument(
        "pattern",
        nargs="?",
        default="*",
        metavar="PATTERN",
        help="only the services whose name (context/name) matches, as in the shell (robot1/*)",
    )
    p.add_argument(
        "--brief", action="store_true", help="no operations: one line per object, event and set"
    )
    p.add_argument("--json", action="store_true", help="print it all as JSON")
    add_ros2_flag(p, "list")
    return p


def list_main(argv: Sequence[str]) -> int:
    if wants_ros2(argv):
        from miro_gen.cli import live_ros2

        return live_ros2.list_main(argv)
    p = parser()
    robot, ns = connect(p, "miro list", argv)
    try:
        services = [s for s in robot.services() if _matches(s.name, ns.pattern)]
        entries = robot.entries()
        if ns.json:
            print(json.dumps(_json(robot, services, entries), indent=2))
        else:
            _print(robot, services, entries, ns.brief)
    except LiveError as e:
        print(f"miro list: {e}", file=sys.stderr)
        return 1
    finally:
        robot.close()
    return 0


def _matches(name: str, pattern: str) -> bool:
    return fnmatch.fnmatchcase(name, pattern) or fnmatch.fnmatchcase(name.split("/")[-1], pattern)


def _print(robot: Robot, services: list[Running], entries: list[Any], brief: bool) -> None:
    from miro_gen.transport.events import CHANNEL_REPO_ID

    accounted = {s.entry.name for s in services}
    for s in services:
        d = s.description
        if d is None:
            print(f"{s.name}  (does not answer: {s.error})")
            continue
        up = duration_text(max(time.time() - d.started, 0))
        print(f"{s.name}  (pid {d.pid} on {d.host}, up {up})  {d.program}")
        if d.objects:
            print("  objects:")
        for obj in d.objects:
            accounted.add(obj.name)
            label = obj.name or f"(not bound; key {obj.key.decode('latin-1')})"
            print(f"    {label}  {obj.repo_id}")
            if brief or not obj.interface_hash:
                continue
            service = robot.service_at(s.entry.endpoint)
            try:
                ops = _operations_via(robot, service, obj)
            except LiveError as e:
                ops = [f"(no operations: {e})"]
            for text in ops:
                print(f"      {text}")
        if d.offers:
            print("  publishes:")
        for o in d.offers:
            print(f"    {o.domain}/{o.type_name}  {o.payload}  on {o.channel}")
        if d.subscriptions:
            print("  subscribes to:")
        for sub in d.subscriptions:
            print(f"    {sub.domain}/{sub.type_name}  on {sub.channel}")
        if d.parameters:
            print("  parameters:")
        for ps in d.parameters:
            source = f"  (from {ps.document})" if ps.document else "  (defaults)"
            print(f"    {ps.section}/{ps.category}  {ps.type_name}{source}")
    channels = [c for c in entries if c.repo_id == CHANNEL_REPO_ID]
    if channels:
        print("event channels:")
        for c in channels:
            print(f"  {c.name}  at {c.endpoint}")
        accounted.update(c.name for c in channels)
    others = [o for o in entries if o.name not in accounted and "/_services/" not in o.name]
    if others:
        print("other names:")
        for o in others:
            print(f"  {o.name}  {o.repo_id} at {o.endpoint}")
    if not services and not channels and not others:
        print("(nothing is running: the naming service holds no names)")


def _operations_via(robot: Robot, service: Any, obj: Any) -> list[str]:
    """The operations of a served object, from its service's interface schema."""
    import MiroService

    from miro_gen.exceptions import SystemException
    from miro_gen.live.schemas import SchemaError, compile_schema

    try:
        text = service.interface_schema(obj.repo_id)
        compiled = compile_schema(text)
    except (MiroService.NotFound, SystemException, SchemaError) as e:
        raise LiveError(str(getattr(e, "what", e))) from None
    return [s.text() for s in signatures(compiled, obj.repo_id)]


def _json(robot: Robot, services: list[Running], entries: list[Any]) -> dict[str, Any]:
    from miro_gen.live.values import to_plain
    from miro_gen.transport.events import CHANNEL_REPO_ID

    out: dict[str, Any] = {"services": [], "channels": [], "names": []}
    for s in services:
        item: dict[str, Any] = {"name": s.name, "endpoint": s.entry.endpoint}
        if s.description is None:
            item["error"] = s.error
        else:
            item.update(to_plain(s.description))
            service = robot.service_at(s.entry.endpoint)
            for obj, plain in zip(s.description.objects, item["objects"], strict=True):
                try:
                    plain["operations"] = _operations_via(robot, service, obj)
                except LiveError as e:
                    plain["operations_error"] = str(e)
        out["services"].append(item)
    for entry in entries:
        named = {"name": entry.name, "repo_id": entry.repo_id, "endpoint": entry.endpoint}
        out["channels" if entry.repo_id == CHANNEL_REPO_ID else "names"].append(named)
    return out
