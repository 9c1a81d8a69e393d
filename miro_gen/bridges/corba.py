"""Relaying events between a CORBA event channel and a miro-gen event channel.

Why a bridge as well as `CosEventSupplier`/`CosEventConsumer`: the services of a robot publish
through miro-gen's structured events (domain, type name, sequence numbers, subscriptions that
let suppliers skip work), which CORBA's CosEvent channels do not have; one bridge process lets
every existing supplier and consumer, on either side, see the other side's events without a
change to its code. Towards CORBA, each event's payload is pushed as an `any` (its TypeCode made
from its data schema); from CORBA, each `any` holding a generated type is published as an event
named after the type (`Point` for `Peer::Point`, or the name given), in the bridge's domain.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass, field
from typing import Any

from miro_gen.corba.events import CosEventConsumer, CosEventSupplier, EventChannel
from miro_gen.log import PeerWarnings, logger
from miro_gen.service.server import Server
from miro_gen.transport.events import (
    KEEP_ALL,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)
from miro_gen.transport.events import EventChannel as MiroChannel  # (a miro-gen channel)

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts
QUEUE = 10_000  # events waiting to go to the CORBA channel; beyond, the newest are dropped


@dataclass
class Routes:
    """What goes where: `to_corba` lists (domain, type) subscriptions on the miro-gen channel;
    `from_corba` maps the types taken from the CORBA channel (IDL name, scoped name or
    repository id; `*` any) to the event type names they are published as ("": the IDL name)."""

    to_corba: list[tuple[str, str]] = field(default_factory=list)
    from_corba: dict[str, str] = field(default_factory=dict)

    def overlap(self) -> set[str]:
        """Type names bridged both ways (which would go round in circles)."""
        ours = {t for _, t in self.to_corba}
        theirs = {(v or k) for k, v in self.from_corba.items()}
        if ("*" in ours and theirs) or ("*" in theirs and ours):
            return {"*"}
        return ours & theirs


class _ToCorba(StructuredPushConsumer):
    """Takes events from the miro-gen channel (on the reactor thread) and hands them to a thread
    that pushes them into the CORBA channel, so that a slow channel never blocks the reactor."""

    def __init__(self, channel: MiroChannel, supplier: CosEventSupplier) -> None:
        super().__init__(channel, depth=KEEP_ALL)  # every event is relayed, none skipped
        self.supplier = supplier
        self.outbox: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self.waiting = 0
        self.overflowed = 0  # events not relayed because the CORBA side fell QUEUE behind
        self.thread = threading.Thread(target=self._run, name="miro-bridge", daemon=True)
        self.thread.start()

    def push_structured_event(self, event: StructuredEvent) -> None:
        if self.waiting >= QUEUE:
            self.overflowed += 1
            return
        self.waiting += 1
        self.outbox.put(event.payload)

    def _run(self) -> None:
        while True:
            payload = self.outbox.get()
            self.waiting -= 1
            if payload is None:
                return
            try:
                self.supplier.push(payload)
            except Exception as e:
                _peer_warnings.warning(
                    "cannot push a %s into the CORBA channel: %s", type(payload).__name__, e
                )

    def stop(self) -> None:
        self.outbox.put(None)
        self.thread.join(5)
        self.close()


class _FromCorba(CosEventConsumer):
    """Takes `any` values from the CORBA channel and publishes those of the routed types."""

    def __init__(
        self, channel: EventChannel, supplier: StructuredPushSupplier, routes: dict[str, str]
    ) -> None:
        self.supplier = supplier
        self.routes = routes
        self.skipped: set[str] = set()
        super().__init__(channel)

    def push_event(self, value: Any) -> None:
        name = getattr(value, "_type_name", "")
        if not name or not hasattr(value, "serialize"):
            self._skip(type(value).__name__, "it is no generated IDL type")
            return
        repo_id = getattr(value, "_repo_id", "")
        short = name.rpartition("::")[2]
        for key in (repo_id, name, short, "*"):
            if key in self.routes:
                self.supplier.push(self.routes[key] or short, value)
                return
        self._skip(name, "it is not routed (--from-corba)")

    def _skip(self, what: str, why: str) -> None:
        if what not in self.skipped:
            self.skipped.add(what)
            _log.notice("events of %s from the CORBA channel are not bridged: %s", what, why)


class Bridge:
    """A running bridge between `corba` (a CORBA event channel) and `channel` (a miro-gen one)
    of `server`, along `routes`."""

    def __init__(
        self, server: Server, corba: EventChannel, channel: MiroChannel, routes: Routes
    ) -> None:
        self.to_corba: _ToCorba | None = None
        self.from_corba: _FromCorba | None = None
        self.supplier: CosEventSupplier | None = None
        if routes.to_corba:
            self.supplier = CosEventSupplier(corba)
            self.to_corba = _ToCorba(channel, self.supplier)
            self.to_corba.set_subscriptions(routes.to_corba)
        if routes.from_corba:
            publisher = StructuredPushSupplier(channel, server.options.naming_context)
            self.from_corba = _FromCorba(corba, publisher, routes.from_corba)

    def close(self) -> None:
        if self.to_corba is not None:
            self.to_corba.stop()
        if self.supplier is not None:
            self.supplier.close()
        if self.from_corba is not None:
            self.from_corba.close()
            self.from_corba.supplier.close()
