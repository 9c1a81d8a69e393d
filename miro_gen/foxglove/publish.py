"""What Foxglove clients publish, into the event channel as `miro pub` publishes: a client
channel `[DOMAIN/]TYPE` (the bridge's naming context when no domain is given) becomes events of
TYPE from DOMAIN.

The payload's type is the one the running suppliers of that topic offer, else the `omgidl`
schema the client advertised with its channel (compiled as schema text from elsewhere is).
Messages are `cdr` (checked by decoding them with that type: what does not decode is logged
and dropped) or `json` (a mapping of the type's members, as `miro pub` reads a value).
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from miro_gen.live.schemas import SchemaError, compile_schema, data_class
from miro_gen.live.values import from_plain
from miro_gen.log import PeerWarnings, logger
from miro_gen.transport.events import EventChannel, StructuredPushSupplier

_log = logger("MIRO")
_warnings = PeerWarnings(_log)
ENCODINGS = ("cdr", "json")
# A supplier made a moment ago has not heard its channel's subscriptions yet: what it is given
# to publish within GRACE seconds of its start, while nobody seems to listen, waits (at most
# HELD events) instead of being dropped as unheard.
GRACE = 2.0
HELD = 1000
RETRY = 0.02  # seconds between looks at the held events


@dataclass
class _Advertised:
    domain: str
    type_name: str
    encoding: str
    cls: type[Any]


class ClientPublishing:
    """Client channels (advertised by Foxglove clients) and the suppliers that publish what
    arrives on them; `schema_of(topic)` gives the (payload name, schema text) of an offered
    topic."""

    def __init__(
        self,
        channel: EventChannel,
        default_domain: str,
        schema_of: Callable[[str], tuple[str, str] | None],
    ) -> None:
        self.channel = channel
        self.reactor = channel.reactor
        self.default_domain = default_domain
        self.schema_of = schema_of
        self._lock = threading.Lock()
        self._channels: dict[tuple[int, int], _Advertised] = {}
        self._suppliers: dict[str, tuple[StructuredPushSupplier, float]] = {}
        self._held: deque[tuple[str, str, Any]] = deque(maxlen=HELD)  # the reactor's
        self.published = 0
        self.dropped = 0

    def advertise(
        self,
        client: int,
        channel_id: int,
        topic: str,
        encoding: str,
        schema_name: str,
        schema: bytes | None,
    ) -> None:
        domain, _, type_name = topic.strip("/").rpartition("/")
        domain = domain or self.default_domain
        if not type_name or encoding not in ENCODINGS:
            _warnings.warning(
                "foxglove: client %d: cannot publish %s as %r (DOMAIN/TYPE, cdr or json)",
                client,
                topic,
                encoding,
            )
            return
        offered = self.schema_of(f"{domain}/{type_name}")
        try:
            if offered is not None:
                cls = data_class(compile_schema(offered[1]), offered[0])
            elif schema and schema_name:
                cls = data_class(compile_schema(schema.decode()), schema_name)
            else:
                raise SchemaError("nobody offers it and the client gave no omgidl schema")
        except (SchemaError, UnicodeDecodeError) as e:
            _warnings.warning("foxglove: client %d: cannot publish %s: %s", client, topic, e)
            return
        with self._lock:
            self._channels[(client, channel_id)] = _Advertised(domain, type_name, encoding, cls)
        # The supplier now, not at the first message: its subscriptions have time to arrive,
        # and that message is not dropped as one nobody listens to.
        self.reactor.call_soon(self._supplier, domain)
        _log.info("foxglove: client %d publishes %s/%s (%s)", client, domain, type_name, encoding)

    def unadvertise(self, client: int, channel_id: int) -> None:
        with self._lock:
            self._channels.pop((client, channel_id), None)

    def message(self, client: int, channel_id: int, data: bytes) -> None:
        """A message on a client channel (a Foxglove server thread): decoded here, pushed on
        the reactor thread."""
        with self._lock:
            a = self._channels.get((client, channel_id))
        if a is None:
            return
        try:
            if a.encoding == "cdr":
                payload = a.cls.deserialize(data)
            else:
                payload = from_plain(a.cls, json.loads(data.decode()), "message")
        except Exception as e:  # whatever a client sends: logged and dropped
            self.dropped += 1
            _warnings.warning(
                "foxglove: client %d: dropped a message on %s/%s: %s: %s",
                client,
                a.domain,
                a.type_name,
                type(e).__name__,
                e,
            )
            return
        self.reactor.call_soon(self._push, a.domain, a.type_name, payload)

    def _supplier(self, domain: str) -> tuple[StructuredPushSupplier, float]:
        made = self._suppliers.get(domain)
        if made is None:
            supplier = StructuredPushSupplier(self.channel, domain_name=domain)
            made = self._suppliers[domain] = (supplier, time.monotonic())
        return made

    def _push(self, domain: str, type_name: str, payload: Any) -> None:
        supplier, born = self._supplier(domain)
        young = time.monotonic() - born < GRACE
        if self._held or (young and not supplier.has_subscribers(type_name)):
            if not self._held:
                self.reactor.schedule_timer(RETRY, 0, self._release)
            self._held.append((domain, type_name, payload))  # in order, behind those held
            return
        supplier.push(type_name, payload)
        self.published += 1

    def _release(self, _: object = None) -> None:
        """Publish the held events whose suppliers now hear a subscription or are no longer
        young; look again later for the others."""
        while self._held:
            domain, type_name, payload = self._held[0]
            supplier, born = self._supplier(domain)
            if not supplier.has_subscribers(type_name) and time.monotonic() - born < GRACE:
                self.reactor.schedule_timer(RETRY, 0, self._release)
                return
            self._held.popleft()
            supplier.push(type_name, payload)
            self.published += 1

    def close(self) -> None:
        for supplier, _ in self._suppliers.values():
            supplier.close()
        self._suppliers.clear()
