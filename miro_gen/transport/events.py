"""Event channels: suppliers push typed events, any number of consumers receive those they
subscribe to (Miro's EventChannel, StructuredPushSupplier, StructuredPushConsumer).

A channel is a ZeroMQ XSUB/XPUB proxy, run by libzmq in a thread of the process that hosts it,
and bound in the naming service (transport.channels; docs/PROTOCOL.md, "Event channels").
Suppliers connect XPUB sockets to its XSUB side, so subscriptions travel back to them:
`has_subscribers()` tells a supplier whether anyone listens, and `push()` skips encoding when
nobody does. Consumers connect SUB sockets to its XPUB side.

Each event carries its domain (by convention the supplier's naming context: the robot), its type
name, the type hash of its payload, a sequence number per supplier and type (so consumers count
what they missed), the source time stamp and the publish time (the bytes: transport.event_frames).
Events pushed within one reactor turn leave in one frame per topic (split at MAX_BATCH_EVENTS /
MAX_BATCH_BYTES), so throughput is not capped at one ZeroMQ message per event; at low rates that is
one event per frame, as fast as a single message; an event of LARGE_EVENT bytes or more travels
alone, copied once into its frame and decoded in place from the consumer's. Slow consumers never
block suppliers: the supplier's queue and ZeroMQ's are bounded (in bytes: transport.sockets), what
overflows is dropped and counted (`StructuredPushSupplier.dropped`), and the sequence numbers make
the drops visible (`StructuredPushConsumer.missed`). A consumer keeps the events waiting for its
handler as its quality of service says (keep-last depth, latest-only: transport.event_queue), so a
slow one gets recent events and counts what it skipped (`dropped`, `lag`). Suppliers and consumers
find their channel again when its host restarts elsewhere (transport.channel_link).
"""

from miro_gen.transport.channels import CHANNEL_REPO_ID as CHANNEL_REPO_ID
from miro_gen.transport.channels import DEFAULT_CHANNEL as DEFAULT_CHANNEL
from miro_gen.transport.channels import PROXY_HWM as PROXY_HWM
from miro_gen.transport.channels import ChannelHost as ChannelHost
from miro_gen.transport.channels import EventChannel as EventChannel
from miro_gen.transport.channels import EventChannelFactory as EventChannelFactory
from miro_gen.transport.channels import resolve_channel as resolve_channel
from miro_gen.transport.event_consumer import ANY as ANY
from miro_gen.transport.event_consumer import HOLD_BYTES as HOLD_BYTES
from miro_gen.transport.event_consumer import HOLD_FRAMES as HOLD_FRAMES
from miro_gen.transport.event_consumer import TURN_EVENTS as TURN_EVENTS
from miro_gen.transport.event_consumer import TURN_FRAMES as TURN_FRAMES
from miro_gen.transport.event_consumer import StructuredEvent as StructuredEvent
from miro_gen.transport.event_consumer import StructuredPushConsumer as StructuredPushConsumer
from miro_gen.transport.event_consumer import subscription_prefix as subscription_prefix
from miro_gen.transport.event_frames import topic as topic
from miro_gen.transport.event_queue import DEFAULT_DEPTH as DEFAULT_DEPTH
from miro_gen.transport.event_queue import KEEP_ALL as KEEP_ALL
from miro_gen.transport.event_supplier import HWM as HWM
from miro_gen.transport.event_supplier import LARGE_EVENT as LARGE_EVENT
from miro_gen.transport.event_supplier import MAX_BATCH_BYTES as MAX_BATCH_BYTES
from miro_gen.transport.event_supplier import MAX_BATCH_EVENTS as MAX_BATCH_EVENTS
from miro_gen.transport.event_supplier import MAX_PREFIX as MAX_PREFIX
from miro_gen.transport.event_supplier import MAX_SUBSCRIPTIONS as MAX_SUBSCRIPTIONS
from miro_gen.transport.event_supplier import QUEUE_BYTES as QUEUE_BYTES
from miro_gen.transport.event_supplier import QUEUE_EVENTS as QUEUE_EVENTS
from miro_gen.transport.event_supplier import StructuredPushSupplier as StructuredPushSupplier
