"""rosidl_parser's reading of `.idl` files, as JSON: run in the ROS 2 environment of
tests/ros2_env.py (it imports rosidl_parser, which miro-gen's environment does not have).

    python rosidl_structs.py SHARE FILE...

prints {FILE: {struct: [members, constants]}} for each FILE (relative to SHARE): the structs of
the messages, services (request, response, event) and actions (goal, result, feedback, feedback
message, and their two services) it declares; members as [name, type, default or null],
constants as [name, type, value]. Types are spelled as miro's side spells them
(tests/rosidl_differential.py): `int32`, `string<8>`, `sequence<T, 4>`, `T[3]`, `pkg::msg::Name`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from rosidl_parser import definition as rd
from rosidl_parser.parser import parse_idl_file


def structs(share: Path, path: str) -> dict[str, Any]:
    content = parse_idl_file(rd.IdlLocator(share, Path(path))).content
    out: dict[str, Any] = {}

    def message(msg: Any) -> None:
        s = msg.structure
        name = "::".join(s.namespaced_type.namespaced_name())
        members = [[m.name, type_name(m.type), default(m)] for m in s.members]
        # rosidl_parser types a string constant `string<len(value)>` (`const string` in the
        # .idl): compared as the `string` it is declared.
        consts = [[c.name, type_name(c.type).split("<")[0], plain(c.value)] for c in msg.constants]
        out[name] = [members, consts]

    def service(srv: Any) -> None:
        for msg in (srv.request_message, srv.response_message, srv.event_message):
            message(msg)

    for el in content.elements:
        if isinstance(el, rd.Message):
            message(el)
        elif isinstance(el, rd.Service):
            service(el)
        elif isinstance(el, rd.Action):
            for msg in (el.goal, el.result, el.feedback, el.feedback_message):
                message(msg)
            service(el.send_goal_service)
            service(el.get_result_service)
    return out


def plain(v: Any) -> Any:
    return v if isinstance(v, bool | int | float | str) else str(v)


def default(m: Any) -> Any:
    return (
        plain(m.get_annotation_value("default")["value"]) if m.has_annotation("default") else None
    )


def type_name(t: Any) -> str:
    if isinstance(t, rd.Array):
        return f"{type_name(t.value_type)}[{t.size}]"
    if isinstance(t, rd.BoundedSequence):
        return f"sequence<{type_name(t.value_type)}, {t.maximum_size}>"
    if isinstance(t, rd.UnboundedSequence):
        return f"sequence<{type_name(t.value_type)}>"
    if isinstance(t, rd.BoundedString):
        return f"string<{t.maximum_size}>"
    if isinstance(t, rd.BoundedWString):
        return f"wstring<{t.maximum_size}>"
    if isinstance(t, rd.UnboundedString):
        return "string"
    if isinstance(t, rd.UnboundedWString):
        return "wstring"
    if isinstance(t, rd.BasicType):
        return str(t.typename)
    if isinstance(t, rd.NamespacedType):
        return "::".join(t.namespaced_name())
    raise TypeError(f"unknown rosidl type {t!r}")


if __name__ == "__main__":
    share = Path(sys.argv[1])
    json.dump({f: structs(share, f) for f in sys.argv[2:]}, sys.stdout)
