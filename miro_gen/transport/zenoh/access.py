"""Access control per robot at the router of `miro naming --zenoh --per-robot ROBOT,...`:
Zenoh's own `access_control`, whose subjects are the common names of the sessions' TLS
certificates (`cert_common_names`; `miro keys new ROBOT --ca FLEET` makes ROBOT's).

Mutual TLS alone lets every certificate of the fleet's CA declare anything. With these rules
the router drops, from a robot's session, every declaration and message that is not its own
(transport.zenoh.keys lays the keys out so that a robot's own ones are told by one chunk):

* queryables and replies only on `miro/call/ROBOT/*` (its processes' objects),
* liveliness tokens only on `miro/alive/ROBOT/*` and `miro/name/ROBOT/*/*` (its processes
  and the names they keep) and `miro/sub/**` (its consumers' subscriptions),
* events (put, delete) only under its own domain, `miro/ev/*/ROBOT/*`;

while it may subscribe, query (call anyone, ask the registry) and hear anything. The
certificate of the router's own key (the fleet's: the base's processes) may do everything.
Any other certificate, even one of the CA, may do nothing: rules list who may, and Zenoh's
default is then to deny. Without TLS there are no certificates to tell robots by: this
needs a key (security.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from miro_gen.transport.zenoh import keys

EVERY_MESSAGE = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)
LISTENING = ("declare_subscriber", "query", "liveliness_query", "declare_liveliness_subscriber")


def _rule(rule_id: str, messages: Sequence[str], flows: Sequence[str], *exprs: str) -> Any:
    return {
        "id": rule_id,
        "messages": list(messages),
        "flows": list(flows),
        "permission": "allow",
        "key_exprs": list(exprs),
    }


def robot_rules(robot: str, n: int) -> list[Any]:
    """The rules of the robot `robot` (its certificate's common name), ids `r<n>-...`."""
    own = keys.escape(robot)
    p = keys.PREFIX
    return [
        _rule(f"r{n}-hear", EVERY_MESSAGE, ["egress"], "**"),
        _rule(f"r{n}-ask", LISTENING, ["ingress"], "**"),
        _rule(f"r{n}-serve", ["declare_queryable", "reply"], ["ingress"], f"{p}/call/{own}/*"),
        _rule(
            f"r{n}-tokens",
            ["liveliness_token"],
            ["ingress"],
            f"{p}/alive/{own}/*",
            f"{p}/name/{own}/*/*",
            f"{p}/sub/**",
        ),
        _rule(f"r{n}-events", ["put", "delete"], ["ingress"], f"{p}/ev/*/{own}/*"),
    ]


def access_control(fleet: str, robots: Sequence[str]) -> Any:
    """Zenoh's `access_control` config: the certificate `fleet` (the router's own key's
    common name) may do everything, each of `robots` only what is its own (above), any other
    nothing."""
    rules = [_rule("fleet", EVERY_MESSAGE, ["ingress", "egress"], "**")]
    subjects: list[Any] = [{"id": "fleet", "cert_common_names": [fleet]}]
    policies = [{"id": "fleet", "rules": ["fleet"], "subjects": ["fleet"]}]
    for n, robot in enumerate(dict.fromkeys(robots)):
        if robot == fleet:
            continue  # (the fleet's key may do everything already)
        mine = robot_rules(robot, n)
        rules += mine
        subjects.append({"id": f"r{n}", "cert_common_names": [robot]})
        policies.append({"id": f"r{n}", "rules": [r["id"] for r in mine], "subjects": [f"r{n}"]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
