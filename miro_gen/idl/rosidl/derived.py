"""The types rosidl derives from a service or an action, added as IDL structs.

rosidl_parser (Kilted, `definition.py`) gives every service `X` (structs `X_Request` and
`X_Response` in `module pkg { module srv {...} }`) an event message `X_Event`, and every action
`X` (`X_Goal`, `X_Result`, `X_Feedback` in `module action`) the services `X_SendGoal` and
`X_GetResult` (requests, responses and events) and the message `X_FeedbackMessage`. The
services and the action themselves are types too in ROS 2's type descriptions
(rosidl_generator_type_description): a service `X` has the fields `request_message`,
`response_message` and `event_message`, an action the fields `goal`, `result`, `feedback`,
`send_goal_service`, `get_result_service` and `feedback_message`; they are added as structs of
those fields, so that each carries its type hash like any message.
"""

from __future__ import annotations

from miro_gen.diagnostics import SourcePos
from miro_gen.idl import ast

SERVICE_INFO = ("service_msgs", "msg", "ServiceEventInfo")
GOAL_ID = ("unique_identifier_msgs", "msg", "UUID")
TIME = ("builtin_interfaces", "msg", "Time")
# The messages each kind of derived type uses, as `pkg/msg/Name`.
NEEDS = {
    "srv": ["/".join(SERVICE_INFO)],
    "action": ["/".join(t) for t in (SERVICE_INFO, GOAL_ID, TIME)],
}

Field = tuple[str, ast.TypeSpec]


def add_derived(definitions: list[ast.Definition], main_file: str) -> list[str]:
    """Add the derived types of the services and actions `main_file` declares (in the modules
    of `definitions` holding them); the messages they need, as `pkg/msg/Name`."""
    needs: list[str] = []
    for top in definitions:
        if not isinstance(top, ast.Module):
            continue
        for inner in top.definitions:
            if isinstance(inner, ast.Module) and inner.name in ("srv", "action"):
                mine = [
                    d.name
                    for d in inner.definitions
                    if isinstance(d, ast.Struct) and d.pos.path == main_file
                ]
                added = _derive(top.name, inner, mine)
                if added:
                    needs += [n for n in NEEDS[inner.name] if n not in needs]
    return needs


def _derive(package: str, module: ast.Module, structs: list[str]) -> bool:
    by_name = {d.name: d for d in module.definitions if isinstance(d, ast.Struct)}
    added = False
    for name in structs:
        base = name.removesuffix("_Request") if module.name == "srv" else name.removesuffix("_Goal")
        if base == name:
            continue
        scope = (package, module.name)
        pos = by_name[name].pos
        if module.name == "srv" and base + "_Response" in by_name:
            module.definitions += _service(scope, base, pos)
            added = True
        elif {base + "_Result", base + "_Feedback"} <= by_name.keys():
            module.definitions += _action(scope, base, pos)
            added = True
    return added


def _service(
    scope: tuple[str, str], name: str, pos: SourcePos, request: list[Field] | None = None,
    response: list[Field] | None = None,
) -> list[ast.Definition]:  # fmt: skip
    """The event and the service struct of service `name` (and its request and response,
    when given)."""
    out: list[ast.Definition] = []
    if request is not None and response is not None:
        out.append(_struct(name + "_Request", request, pos))
        out.append(_struct(name + "_Response", response, pos))
    out.append(
        _struct(
            name + "_Event",
            [
                ("info", _ref(SERVICE_INFO, pos)),
                ("request", _sequence_of_one(_ref((*scope, name + "_Request"), pos), pos)),
                ("response", _sequence_of_one(_ref((*scope, name + "_Response"), pos), pos)),
            ],
            pos,
        )
    )
    out.append(
        _struct(
            name,
            [
                ("request_message", _ref((*scope, name + "_Request"), pos)),
                ("response_message", _ref((*scope, name + "_Response"), pos)),
                ("event_message", _ref((*scope, name + "_Event"), pos)),
            ],
            pos,
        )
    )
    return out


def _action(scope: tuple[str, str], name: str, pos: SourcePos) -> list[ast.Definition]:
    def own(suffix: str) -> ast.TypeSpec:
        return _ref((*scope, name + suffix), pos)

    goal_id = ("goal_id", _ref(GOAL_ID, pos))
    out = _service(
        scope,
        name + "_SendGoal",
        pos,
        [goal_id, ("goal", own("_Goal"))],
        [("accepted", ast.BaseType("boolean")), ("stamp", _ref(TIME, pos))],
    )
    out += _service(
        scope,
        name + "_GetResult",
        pos,
        [goal_id],
        [("status", ast.BaseType("int8")), ("result", own("_Result"))],
    )
    out.append(_struct(name + "_FeedbackMessage", [goal_id, ("feedback", own("_Feedback"))], pos))
    out.append(
        _struct(
            name,
            [
                ("goal", own("_Goal")),
                ("result", own("_Result")),
                ("feedback", own("_Feedback")),
                ("send_goal_service", own("_SendGoal")),
                ("get_result_service", own("_GetResult")),
                ("feedback_message", own("_FeedbackMessage")),
            ],
            pos,
        )
    )
    return out


def _struct(name: str, fields: list[Field], pos: SourcePos) -> ast.Struct:
    return ast.Struct(name, pos, members=[ast.Member(n, t, [], pos) for n, t in fields])


def _ref(parts: tuple[str, ...], pos: SourcePos) -> ast.NamedType:
    return ast.NamedType(ast.ScopedName(parts, True, pos))


def _sequence_of_one(element: ast.TypeSpec, pos: SourcePos) -> ast.SequenceType:
    return ast.SequenceType(element, ast.Literal("int", 1, pos), pos)
