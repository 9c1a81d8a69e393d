"""A fleet's shared events over Zenoh (Miro's NotifyMulticast): which event types of a channel
every robot shares, and the key expressions a consumer of its own robot's channel adds for them.

Miro's NotifyMulticast sent events of chosen types from each robot's channel to the channels of
the other robots (and the base), each under its robot as the domain. Over Zenoh a channel is its
keys (transport.zenoh.keys), so nothing is forwarded: a consumer of `robot2/EventChannel` whose
process shares `ExampleEvent` of `EventChannel` also subscribes to the keys of that type on the
channel `EventChannel` of every other robot (`*/EventChannel`). Suppliers keep the robot's
naming context as their domain, so each robot's events arrive under its own name.

Which types are shared is said per channel (its name without the robot's context), in the
environment or in launch files (`fleet_events`, docs/FLEET.md):

    MIRO_FLEET_EVENTS="EventChannel=Odometry,RangeScan;ExampleEventChannel=*"

This module only reads that text and lays out keys; it imports no Zenoh.
"""

from __future__ import annotations

import os
import re
from typing import Final

from miro_gen.transport.events.frames import topic
from miro_gen.transport.usage import UsageError
from miro_gen.transport.zenoh import keys

FLEET_ENV: Final = "MIRO_FLEET_EVENTS"
ALL: Final = "*"  # every type of the channel
_NAME = re.compile(r"^[^/\s*;=,]+$")  # a channel's or type's name in that text

Shared = dict[str, frozenset[str]]  # channel name (without context) -> its shared types


def check_name(name: str, what: str) -> str:
    """`name` if it can be a channel's (without its context) or type's name here; else why not."""
    if what == "type" and name == ALL:
        return name
    if not _NAME.match(name):
        raise UsageError(f"{what} {name!r} cannot be shared: a name without / * ; = , or spaces")
    return name


def parse(text: str, source: str = FLEET_ENV) -> Shared:
    """The shared types `text` (`CHANNEL=TYPE,TYPE;CHANNEL=*`) names; UsageError (one line,
    naming `source`) for a malformed one."""
    shared: Shared = {}
    for part in filter(None, (p.strip() for p in text.split(";"))):
        channel, eq, types = part.partition("=")
        names = [t.strip() for t in types.split(",") if t.strip()]
        if not eq or not names:
            raise UsageError(f"{source}: {part!r} is not CHANNEL=TYPE,TYPE (or CHANNEL=*)")
        try:
            name = check_name(channel.strip(), "channel")
            shared[name] = frozenset(check_name(t, "type") for t in names)
        except UsageError as e:
            raise UsageError(f"{source}: {e}") from None
    return shared


def from_environment() -> Shared:
    return parse(os.environ.get(FLEET_ENV, ""))


def text_of(shared: Shared) -> str:
    """`shared` as the text `parse` reads (what `miro launch` puts in the environment)."""
    return ";".join(f"{c}={','.join(sorted(t))}" for c, t in sorted(shared.items()))


def fleet_pattern(channel: str) -> str | None:
    """The channel pattern of every robot's channel of the same name (`robot2/EventChannel` ->
    `*/EventChannel`); None for a channel without a context, or a pattern already."""
    if keys.is_pattern(channel) or "/" not in channel:
        return None
    return "*/" + channel.rsplit("/", 1)[1]


def selectors(pattern: str, prefix: bytes, types: frozenset[str]) -> list[tuple[str, bytes]]:
    """What a consumer's subscription `prefix` (transport.events.consumer.subscription_prefix)
    adds on the fleet's channel `pattern` for the shared `types`: (key expression, the prefix
    of the liveliness token that suppliers count) pairs. A subscription to all domains of one
    type has no prefix of its own: its token says all (b""), and the key expression keeps to
    the type."""
    if ALL in types:
        return [(keys.event_selector(pattern, prefix), prefix)]
    head = f"{keys.PREFIX}/ev/{keys.channel_chunk(pattern)}"
    fields = prefix.split(b"\0")
    if not prefix:
        return [(f"{head}/*/{keys.escape(t)}", b"") for t in sorted(types)]
    domain = fields[0].decode()
    if len(fields) == 2:  # every type of one domain: the shared ones
        return [
            (f"{head}/{keys.escape(domain)}/{keys.escape(t)}", topic(domain, t))
            for t in sorted(types)
        ]
    type_name = fields[1].decode()
    if type_name not in types:
        return []
    return [(keys.event_selector(pattern, prefix), prefix)]
