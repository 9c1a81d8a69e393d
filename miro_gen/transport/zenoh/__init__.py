"""The Zenoh backbone: the same calls, names and events as the ZeroMQ one (`miro_gen.transport`),
carried by Eclipse Zenoh (`--transport zenoh`, `MIRO_TRANSPORT=zenoh`; docs/FLEET.md).

Its parts plug into the seams of `service.backbone` and `transport.events.links`: the key
expressions every part uses (`keys`), a process's session (`session`), calls over queryables
(`invoker`, `adapter`), names kept with a liveliness token each (`names`), event links
(`links`) and the types a fleet shares (`fleet`), and the naming registry hosted beside the
Zenoh router in `miro naming --zenoh` (`registry`). Stubs, skeletons, suppliers, consumers
and the naming table are the ZeroMQ backbone's own; what changes is what carries their bytes.

Zenoh runs its callbacks on its own threads, and a callback that blocks or publishes has
deadlocked interpreters (zenoh-python #434, #106): every callback here only hands its sample
or query to a queue or to the process's reactor, and returns.
"""
