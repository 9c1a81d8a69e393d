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
* of the registry's keys per owner only its own, `miro/@registry/ROBOT` (query, and hear the
  reply): `**` matches no verbatim chunk (`@registry`), so the rule that lets a robot query
  anything does not let it ask another robot's;

while it may subscribe, query (call anyone, resolve and list names) and hear anything. The
certificate of the router's own key (the fleet's: the base's processes) may do everything.
Any other certificate, even one of the CA, may do nothing: rules list who may, and Zenoh's
default is then to deny. Without TLS there are no certificates to tell robots by: this
needs a key (security.py).

Names (`PerRobot`): since a binding operation reaches the registry on the key of the
certificate that asked, the registry takes that certificate's name as the caller's principal
(`cert:ROBOT`: owners, quotas per robot), lets a robot bind only names in its own context
(`ROBOT/...`) and the fleet's certificate any, and refuses binding operations on the open
registry key (`zenoh/naming`: anyone may ask there, so it cannot tell who).

What Zenoh denies it drops without a word to either side, and logs only at Rust's trace
level (its `access_control` interceptor, which zenoh-python cannot route into Python's
logging): a process learns of a denial by the silence, and says so (`denied_hint`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

from miro_gen.transport.rpc.caller import Caller
from miro_gen.transport.zenoh import keys

PRINCIPAL_PREFIX: Final = "cert:"  # a principal told by the router's access control

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
        _rule(f"r{n}-bind", ["query"], ["ingress"], keys.registry_key(robot)),
        _rule(f"r{n}-bound", ["reply"], ["egress"], keys.registry_key(robot)),
    ]


def access_control(fleet: str, robots: Sequence[str]) -> Any:
    """Zenoh's `access_control` config: the certificate `fleet` (the router's own key's
    common name) may do everything, each of `robots` only what is its own (above), any other
    nothing."""
    rules = [_rule("fleet", EVERY_MESSAGE, ["ingress", "egress"], "**", keys.REGISTRY_KEYS)]
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


def denied_hint(owner: str, key: str) -> str:
    """What a process with the certificate `owner` says when the router is silent on `key`."""
    return (
        f"the router's access control (`miro naming --zenoh --per-robot`) may deny the "
        f"certificate {owner} the key {key}: is {owner} listed there?"
    )


class PerRobot:
    """Who binds which names at the registry of a router with access control per robot:
    `fleet` (the router's own certificate's common name) any, each of `robots` only in its
    own context, through the registry's key of its certificate."""

    def __init__(self, fleet: str, robots: Sequence[str]) -> None:
        self.fleet = fleet
        self.robots = frozenset(robots)

    @staticmethod
    def caller(key: str) -> Caller | None:
        """The caller of a query on `key`: the certificate that the registry key names, which
        the router let ask there (None: not a registry key per owner)."""
        owner = keys.registry_owner(key)
        return None if owner is None else Caller(PRINCIPAL_PREFIX + owner, True)

    def refusal(self, caller: Caller, name: str | None) -> str | None:
        """Why `caller` may not bind (or unbind, renew) `name` (None: a renewal), or None
        when it may."""
        if not caller.verified or not caller.principal.startswith(PRINCIPAL_PREFIX):
            return (
                "with access control per robot, names are bound through the registry's key "
                "of the caller's certificate (zenoh/naming@NAME), where the router tells "
                "who asks: an older miro-gen?"
            )
        owner = caller.principal[len(PRINCIPAL_PREFIX) :]
        if owner != self.fleet and owner not in self.robots:  # (the router denies it anyway)
            return f"the certificate {owner} is not one of --per-robot's"
        if name is None or owner == self.fleet or name.startswith(f"{owner}/"):
            return None
        return (
            f"the certificate {owner} binds names only in its own context ({owner}/...), "
            f"not {name} (`miro naming --per-robot`; run it with -MNC {owner})"
        )
