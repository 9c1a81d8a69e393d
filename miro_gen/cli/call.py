"""`miro call NAME OPERATION [ARG...]`: call an operation of a running object from the shell,
with no generated code here: the object's service gives its interface schema, compiled once
and cached (miro_gen.live)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.eventargs import add_length_options, length_limit
from miro_gen.cli.live_ros2 import add_ros2_flag, wants_ros2
from miro_gen.cli.liveargs import connect
from miro_gen.live.remote import LiveError, Robot
from miro_gen.live.show import Signature, dump, flow, signatures
from miro_gen.live.values import from_plain, hints, to_plain

COMMON = "Accepts the common options (--naming tcp://HOST:PORT, -MNC NAME, -MLL N)."


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro call",
        description="Call OPERATION of the object bound as NAME and print what it returns. "
        "Each ARG is one in/inout parameter, read as YAML (numbers, true/false, [lists], "
        "{mappings} for structs, {branch: value} for unions, enumerators by name); strings "
        "are taken as written. A single mapping of the parameters' names, or a list of them, "
        "also does; - reads that from the standard input. Without OPERATION, lists the "
        "operations. " + COMMON,
    )
    p.add_argument("name", metavar="NAME", help="the object's name (robot1/ExampleA, ExampleA)")
    p.add_argument("operation", metavar="OPERATION", nargs="?", help="the operation to call")
    p.add_argument("args", metavar="ARG", nargs="*", help="its in and inout parameters")
    p.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to wait (default 10)"
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON (sequences whole)")
    add_length_options(p)
    add_ros2_flag(p, "call", "services")
    return p


def call_main(argv: Sequence[str]) -> int:
    if wants_ros2(argv):
        from miro_gen.cli import call_ros2

        return call_ros2.call_main(argv)
    p = parser()
    robot, ns = connect(p, "miro call", argv)
    if ns.timeout <= 0:
        p.error("--timeout must be more than 0 seconds")
    length_limit(p, ns)  # checked
    robot.timeout = ns.timeout
    try:
        return _call(robot, ns)
    except LiveError as e:
        print(f"miro call: {e}", file=sys.stderr)
        return 1
    finally:
        robot.close()


def _call(robot: Robot, ns: argparse.Namespace) -> int:
    from miro_gen.exceptions import SystemException, UserException
    from miro_gen.transport.events import CHANNEL_REPO_ID

    entry = robot.resolve(ns.name)
    if entry.repo_id == CHANNEL_REPO_ID:
        raise LiveError(f"{entry.name} is an event channel: see miro pub and miro echo")
    stub, compiled = robot.stub(entry)
    ops = signatures(compiled, entry.repo_id)
    if ns.operation is None:
        print(f"{entry.name}: {entry.repo_id} at {entry.endpoint}")
        for op in ops:
            print(f"  {op.text()}")
        return 0
    found = [o for o in ops if o.name == ns.operation]
    if not found:
        known = ", ".join(o.name for o in ops) or "none"
        raise LiveError(f"{entry.repo_id} has no operation {ns.operation} (it has: {known})")
    op = found[0]
    method = getattr(stub, _py_name(stub, op.name))
    args = _arguments(op, hints(method), ns.args, robot)
    try:
        result = method(*args)
    except UserException as e:
        raised = to_plain(e)
        fields = f": {flow(raised)}" if raised else ""
        print(f"{entry.name} {op.name} raised {e._repo_id}{fields}", file=sys.stderr)
        return 1
    except SystemException as e:
        raise LiveError(f"{entry.name} {op.name}: {e}") from None
    names = op.results
    if not names:
        return 0
    values = [result] if len(names) == 1 else list(result)
    limit = None if ns.json or ns.full_length else ns.truncate_length
    results = {n: to_plain(v, limit) for n, v in zip(names, values, strict=True)}
    print(dump(results["return"] if names == ["return"] else results, ns.json))
    return 0


def _py_name(stub: Any, name: str) -> str:
    """The stub's method for an IDL operation (a Python keyword gets an underscore)."""
    return name if hasattr(stub, name) else f"_{name}"


def _arguments(op: Signature, types: dict[str, Any], words: list[str], robot: Robot) -> list[Any]:
    """The call's arguments from the shell's words."""
    inputs = op.inputs
    names = [p["name"] for p in inputs]
    py_names = [n if n in types else f"_{n}" for n in names]
    if words == ["-"]:
        words = [sys.stdin.read()]
    if len(words) == 1 and len(inputs) > 1:
        given = _yaml(words[0], "the arguments")
        if isinstance(given, dict):
            unknown = [k for k in given if k not in names]
            missing = [n for n in names if n not in given]
            if unknown or missing:
                raise LiveError(
                    f"{op.name} takes {', '.join(names)}"
                    + (f"; no parameter {unknown[0]}" if unknown else f"; {missing[0]} missing")
                )
            words_values = [given[n] for n in names]
        elif isinstance(given, list) and len(given) == len(inputs):
            words_values = list(given)
        else:
            raise LiveError(_usage(op))
        plain_values = words_values
    elif len(words) == len(inputs):
        plain_values = [
            w if types.get(py) is str else _yaml(w, name)
            for w, py, name in zip(words, py_names, names, strict=True)
        ]
    else:
        raise LiveError(_usage(op))

    def resolve(text: str, cls: type[Any]) -> Any:
        target = robot.resolve(text)
        from miro_gen.runtime.cdr import ObjectRef

        return cls(ObjectRef(target.repo_id, target.endpoint, target.key), robot.client.invoker)

    try:
        return [
            from_plain(types.get(py), value, name, resolve)
            for value, py, name in zip(plain_values, py_names, names, strict=True)
        ]
    except ValueError as e:
        raise LiveError(f"{op.name}: {e}") from None


def _yaml(text: str, what: str) -> Any:
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        where = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise LiveError(f"cannot read {what} {text!r}: {where}") from None


def _usage(op: Signature) -> str:
    n = len(op.inputs)
    takes = "no arguments" if n == 0 else f"{n} argument{'s' if n > 1 else ''}"
    return f"{op.name} takes {takes}: {op.text()}"
