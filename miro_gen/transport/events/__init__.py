"""Event channels: suppliers push typed events, any number of consumers receive those they
subscribe to (Miro's EventChannel, StructuredPushSupplier, StructuredPushConsumer).

A channel is a ZeroMQ XSUB/XPUB proxy, run by libzmq in a thread of the process that hosts it,
and bound in the naming service (transport.events.channels; docs/PROTOCOL.md, "Event channels").
Suppliers connect XPUB sockets to its XSUB side, so subscriptions travel back to them:
`has_subscribers()` tells a supplier whether anyone listens, and `push()` skips encoding when
nobody does. Consumers connect SUB sockets to its XPUB side.

Each event carries its domain (by convention the supplier's naming context: the robot), its type
name, the type hash of its payload, a sequence number per supplier and type (so consumers count
what they missed), the source time stamp and the publish time (the bytes: transport.events.frames).
Events pushed within one reactor turn leave in one frame per topic (split at MAX_BATCH_EVENTS /
MAX_BATCH_BYTES; a long turn of pushes on the reactor thread sends every EARLY_FLUSH_BYTES, so
that the network and the consumers need not wait for its end), so throughput is not capped at
one ZeroMQ message per event; at low rates that is
one event per frame, as fast as a single message; an event of LARGE_EVENT bytes or more travels
alone, copied once into its frame and decoded in place from the consumer's; between processes of
one host it is written into a shared-memory ring instead and only a descriptor travels
(transport.shm). Slow consumers never
block suppliers: the supplier's queue and ZeroMQ's are bounded (in bytes: transport.sockets), what
overflows is dropped and counted (`StructuredPushSupplier.dropped`), and the sequence numbers make
the drops visible (`StructuredPushConsumer.missed`). A consumer keeps the events waiting for its
handler as its quality of service says (keep-last depth, latest-only: transport.events.queue), so a
slow one gets recent events and counts what it skipped (`dropped`, `lag`); a keep-all one on the
host of its suppliers returns credits, which hold their frames back within a bound instead of
letting the channel drop them (transport.events.credits). Suppliers and consumers
find their channel again when its host restarts elsewhere (transport.events.channel_link).

This is the events part's face: the names services import, each loaded from its module on
first use, so that the log tools, which need only the frames (`frames`), do not load the rest.
"""

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from miro_gen.transport.events.channels import CHANNEL_REPO_ID as CHANNEL_REPO_ID
    from miro_gen.transport.events.channels import DEFAULT_CHANNEL as DEFAULT_CHANNEL
    from miro_gen.transport.events.channels import PROXY_HWM as PROXY_HWM
    from miro_gen.transport.events.channels import ChannelHost as ChannelHost
    from miro_gen.transport.events.channels import EventChannel as EventChannel
    from miro_gen.transport.events.channels import EventChannelFactory as EventChannelFactory
    from miro_gen.transport.events.channels import resolve_channel as resolve_channel
    from miro_gen.transport.events.consumer import ANY as ANY
    from miro_gen.transport.events.consumer import HOLD_BYTES as HOLD_BYTES
    from miro_gen.transport.events.consumer import HOLD_FRAMES as HOLD_FRAMES
    from miro_gen.transport.events.consumer import TURN_EVENTS as TURN_EVENTS
    from miro_gen.transport.events.consumer import TURN_FRAMES as TURN_FRAMES
    from miro_gen.transport.events.consumer import StructuredPushConsumer as StructuredPushConsumer
    from miro_gen.transport.events.consumer import subscription_prefix as subscription_prefix
    from miro_gen.transport.events.event import StructuredEvent as StructuredEvent
    from miro_gen.transport.events.frames import topic as topic
    from miro_gen.transport.events.queue import DEFAULT_DEPTH as DEFAULT_DEPTH
    from miro_gen.transport.events.queue import KEEP_ALL as KEEP_ALL
    from miro_gen.transport.events.supplier import HWM as HWM
    from miro_gen.transport.events.supplier import LARGE_EVENT as LARGE_EVENT
    from miro_gen.transport.events.supplier import MAX_BATCH_BYTES as MAX_BATCH_BYTES
    from miro_gen.transport.events.supplier import MAX_BATCH_EVENTS as MAX_BATCH_EVENTS
    from miro_gen.transport.events.supplier import MAX_PREFIX as MAX_PREFIX
    from miro_gen.transport.events.supplier import MAX_SUBSCRIPTIONS as MAX_SUBSCRIPTIONS
    from miro_gen.transport.events.supplier import QUEUE_BYTES as QUEUE_BYTES
    from miro_gen.transport.events.supplier import QUEUE_EVENTS as QUEUE_EVENTS
    from miro_gen.transport.events.supplier import StructuredPushSupplier as StructuredPushSupplier

# Each name's module, for __getattr__ (tests/project/test_architecture.py checks it against the
# above).
_HOMES = {
    "CHANNEL_REPO_ID": "channels",
    "DEFAULT_CHANNEL": "channels",
    "PROXY_HWM": "channels",
    "ChannelHost": "channels",
    "EventChannel": "channels",
    "EventChannelFactory": "channels",
    "resolve_channel": "channels",
    "ANY": "consumer",
    "HOLD_BYTES": "consumer",
    "HOLD_FRAMES": "consumer",
    "TURN_EVENTS": "consumer",
    "TURN_FRAMES": "consumer",
    "StructuredEvent": "event",
    "StructuredPushConsumer": "consumer",
    "subscription_prefix": "consumer",
    "topic": "frames",
    "DEFAULT_DEPTH": "queue",
    "KEEP_ALL": "queue",
    "HWM": "supplier",
    "LARGE_EVENT": "supplier",
    "MAX_BATCH_BYTES": "supplier",
    "MAX_BATCH_EVENTS": "supplier",
    "MAX_PREFIX": "supplier",
    "MAX_SUBSCRIPTIONS": "supplier",
    "QUEUE_BYTES": "supplier",
    "QUEUE_EVENTS": "supplier",
    "StructuredPushSupplier": "supplier",
}


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value
    return value
