"""The heart of a notification channel: where events come in from either door and go out to
the CORBA consumers whose subscriptions and filters want them.

An event from a CORBA supplier (`from_corba`) is read as far as routing needs: its names and its
`remainder_of_body`'s TypeCode. Its value is copied once into the generated type's CDR for the
other door (`Backbone.publish`, the ZeroMQ channel), when a generated type has that TypeCode's
repository id; an event of a type no generated code knows is counted (`unknown`) and reaches the
CORBA consumers only. To CORBA consumers the event goes on as it came (re-laid out only when it
came big-endian or misaligned, from GIOP 1.0/1.1). An event from the other door
(`from_backbone`, a generated type's CDR) gets the header and TypeCode of its topic, made once,
in front of its payload, which is copied as it is when its alignment allows.

Which consumers want an event is decided by event type first (each consumer proxy's
subscriptions, cached per topic until they change), then by filters. What the channel's
consumers subscribe to, on both doors, is what its suppliers learn (`subscriptions`), and the
reverse for offers.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import NamedTuple, Protocol

from miro_gen.corba import anys
from miro_gen.corba import typecode as tcm
from miro_gen.corba.notify.filters import Fields
from miro_gen.corba.notify.wire import (
    ANY_TYPE,
    STRUCTURED_EVENT_TC,
    EventType,
    event_prefix,
    normalised,
    read_head,
)
from miro_gen.corba.servants import HEADER
from miro_gen.corba.typecode import K, TypeCode
from miro_gen.exceptions import MARSHAL
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime.cdr import BE, LE
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)

MAX_ROUTES = 4096  # topics whose consumers are remembered
MAX_TYPECODES = 512  # TypeCodes (as bytes) whose meaning is remembered
MAX_KEY = 4096  # bytes of a TypeCode, or of a topic's names, that a cache keeps as a key
_COMPLEX = {
    K.tk_objref,
    K.tk_struct,
    K.tk_union,
    K.tk_enum,
    K.tk_sequence,
    K.tk_array,
    K.tk_alias,
    K.tk_except,
    K.tk_value,
    K.tk_value_box,
    K.tk_native,
    K.tk_abstract_interface,
    K.tk_local_interface,
}
# Bytes of the TypeCodes of kinds with parameters but no encapsulation (the others: 4).
_FIXED_SIZES: dict[int, int] = {K.tk_string: 8, K.tk_wstring: 8, K.tk_fixed: 8}


class Backbone(Protocol):
    """The channel's other door, as the hub sees it (transport.events.notify_door: ZeroMQ)."""

    def wants(self, domain: str, type_name: str) -> bool:
        """Whether a consumer at the other door subscribes to events of this topic."""
        ...

    def publish(self, source: int, domain: str, type_name: str, cls: type, payload: bytes) -> None:
        """Publish the event of CORBA supplier `source`: `payload` is `cls`'s CDR (with its
        encapsulation header)."""
        ...

    def release(self, source: int) -> None:
        """CORBA supplier `source` is gone."""
        ...

    def want(self, types: frozenset[EventType]) -> None:
        """The CORBA consumers now subscribe to `types`."""
        ...

    def subscriptions(self) -> frozenset[EventType]:
        """What the other door's consumers subscribe to."""
        ...

    def offers(self) -> frozenset[EventType]:
        """What the other door's suppliers were seen publishing."""
        ...


class Outgoing:
    """An event on its way to CORBA consumers: its names and its structured event's CDR,
    little-endian from a multiple of 8."""

    __slots__ = ("body", "fields", "source")

    def __init__(self, fields: Fields, body: bytes, source: int) -> None:
        self.fields = fields
        self.body = body
        self.source = source  # the CORBA supplier proxy it came from; 0: the other door

    def __len__(self) -> int:
        return len(self.body)

    def as_any(self) -> bytes:
        """The event as a plain `any` (for CosEvent-style consumers): the remainder of an event
        that came as an `any` itself (type %ANY), else the whole structured event."""
        out = CdrOutput()
        inp = CdrInput(self.body)
        if self.fields.type_name == ANY_TYPE and not self.fields.domain:
            head = read_head(inp)
            inp.pos = head.body_at
            anys.transcode(tcm.simple(K.tk_any), inp, out, anys.GIOP_REFS, anys.GIOP_REFS)
        else:
            tcm.write_typecode(out, STRUCTURED_EVENT_TC)
            anys.transcode(STRUCTURED_EVENT_TC, inp, out, anys.GIOP_REFS, anys.GIOP_REFS)
        return bytes(out.buf)


class ConsumerProxy(Protocol):
    """What the hub asks of a consumer-side proxy (`proxies.py`)."""

    ident: int

    def subscribed(self) -> frozenset[EventType]: ...

    def deliver(self, event: Outgoing) -> None: ...

    def offers_changed(self) -> None: ...


class SupplierProxy(Protocol):
    """What the hub asks of a supplier-side proxy (`proxies.py`)."""

    ident: int

    def offered(self) -> frozenset[EventType]: ...


class _Remainder(NamedTuple):
    tc: TypeCode
    cls: type | None
    size: int  # bytes of the TypeCode


class _Prefix(NamedTuple):
    data: bytes  # the structured event up to the value of its remainder_of_body
    tc: TypeCode
    as_is: bool  # whether the payload's CDR can follow as it is


class Hub:
    """Routes a channel's events (see the module's documentation). `backbone`: the other
    door, or None for a channel with only this one."""

    def __init__(self, name: str, backbone: Backbone | None = None) -> None:
        self.name = name
        self.backbone = backbone
        self.received = 0  # events from CORBA suppliers
        self.unknown = 0  # ... of a type no generated code has: CORBA consumers only
        self.malformed = 0  # ... that did not read
        self._lock = threading.RLock()
        self._consumers: dict[int, ConsumerProxy] = {}
        self._suppliers: dict[int, SupplierProxy] = {}
        self._routes: dict[tuple[str, str], tuple[ConsumerProxy, ...]] = {}
        self._typecodes: dict[tuple[int, bytes], _Remainder] = {}
        self._prefixes: dict[tuple[str, str, type], _Prefix] = {}
        self._unknown: set[str] = set()
        self.on_subscriptions: list[Callable[[], object]] = []  # the subscriptions changed

    # ---- parties --------------------------------------------------------------------------

    def add_consumer(self, proxy: ConsumerProxy) -> None:
        with self._lock:
            self._consumers[proxy.ident] = proxy
        self.subscriptions_changed()

    def remove_consumer(self, proxy: ConsumerProxy) -> None:
        with self._lock:
            self._consumers.pop(proxy.ident, None)
        self.subscriptions_changed()

    def add_supplier(self, proxy: SupplierProxy) -> None:
        with self._lock:
            self._suppliers[proxy.ident] = proxy
        self.offers_changed()

    def remove_supplier(self, proxy: SupplierProxy) -> None:
        with self._lock:
            self._suppliers.pop(proxy.ident, None)
        if self.backbone is not None:
            self.backbone.release(proxy.ident)
        self.offers_changed()

    def subscriptions_changed(self) -> None:
        """A consumer's subscriptions changed (or one came or went): routes are made anew,
        the other door and the suppliers told."""
        with self._lock:
            self._routes = {}
            wanted = frozenset(t for c in self._consumers.values() for t in c.subscribed())
        if self.backbone is not None:
            self.backbone.want(wanted)
        for fn in list(self.on_subscriptions):
            fn()

    def offers_changed(self) -> None:
        """A supplier's offers changed (or one came or went): the consumers are told."""
        with self._lock:
            consumers = list(self._consumers.values())
        for c in consumers:
            c.offers_changed()

    def others_changed(self) -> None:
        """The other door's subscriptions or offers changed: the suppliers and consumers here
        are told."""
        for fn in list(self.on_subscriptions):
            fn()
        self.offers_changed()

    def subscriptions(self) -> frozenset[EventType]:
        """What every consumer of the channel subscribes to, at both doors."""
        with self._lock:
            here = frozenset(t for c in self._consumers.values() for t in c.subscribed())
        return here | (self.backbone.subscriptions() if self.backbone is not None else frozenset())

    def offers(self) -> frozenset[EventType]:
        """What every supplier of the channel offers, at both doors."""
        with self._lock:
            here = frozenset(t for s in self._suppliers.values() for t in s.offered())
        return here | (self.backbone.offers() if self.backbone is not None else frozenset())

    # ---- events -----------------------------------------------------------------------------

    def from_corba(
        self, source: int, inp: CdrInput, accept: Callable[[Fields], bool] | None = None
    ) -> Outgoing | None:
        """An event a CORBA supplier pushed (`inp` at its start): if `accept` (its supplier's
        filters) lets it in, routed to the consumers here and published at the other door;
        the event as it goes on (None: filtered out). MARSHAL when it does not read."""
        start = inp.pos
        try:
            head = read_head(inp)
            remainder = self._remainder(inp, head.body_at)
        except MARSHAL as e:  # counted, said, and the supplier told (MARSHAL)
            self.malformed += 1
            _peer_warnings.warning("%s: dropped an event that does not read: %s", self.name, e)
            raise
        fields = Fields(head.domain, head.type_name, head.event_name)
        if accept is not None and not accept(fields):
            return None
        self.received += 1
        value_at = head.body_at + remainder.size
        if self.backbone is not None and self.backbone.wants(head.domain, head.type_name):
            self._publish(source, fields, remainder, inp, value_at)
        if inp.e == LE and start % 8 == 0:
            body = bytes(memoryview(inp.data)[start:])
        else:
            inp.pos = start
            body = normalised(inp)
        event = Outgoing(fields, body, source)
        self.deliver(event)
        return event

    def _publish(
        self, source: int, fields: Fields, r: _Remainder, inp: CdrInput, value_at: int
    ) -> None:
        assert self.backbone is not None
        if r.cls is None:
            self.unknown += 1
            if r.tc.id not in self._unknown and len(self._unknown) < 1000:
                self._unknown.add(r.tc.id)
                _peer_warnings.warning(
                    "%s: events %s/%s carry %s, which no generated type has: they reach the "
                    "CORBA consumers only (generate its IDL with miro-idl to publish them)",
                    self.name,
                    fields.domain,
                    fields.type_name,
                    r.tc.id or r.tc.kind.name,
                )
            return
        out = CdrOutput()  # a generated type's CDR: aligned from the end of its header
        try:
            value = CdrInput(inp.data, value_at, inp.e, inp.end)
            anys.transcode(r.tc, value, out, anys.GIOP_REFS, anys.MIRO_REFS)
        except MARSHAL as e:
            self.malformed += 1
            _peer_warnings.warning("%s: an event's value does not read: %s", self.name, e)
            return
        payload = HEADER + out.buf
        self.backbone.publish(source, fields.domain, fields.type_name, r.cls, bytes(payload))

    def from_backbone(self, domain: str, type_name: str, cls: type, payload: bytes) -> None:
        """An event from the other door: `payload` is `cls`'s CDR with its header."""
        p = self._prefixes.get((domain, type_name, cls))
        if p is None:
            p = self._prefix(domain, type_name, cls)
        if p.as_is and payload[1] == 1:
            body = p.data + payload[4:]
        else:
            out = CdrOutput(bytearray(p.data))
            src = CdrInput(payload[4:], 0, LE if payload[1] == 1 else BE)
            anys.transcode(p.tc, src, out, anys.MIRO_REFS, anys.GIOP_REFS)
            body = bytes(out.buf)
        self.deliver(Outgoing(Fields(domain, type_name, ""), body, 0))

    def deliver(self, event: Outgoing) -> None:
        """Hand `event` to every consumer proxy whose subscriptions want its type."""
        f = event.fields
        route = self._routes.get((f.domain, f.type_name))
        if route is None:
            route = self._route(f.domain, f.type_name)
        for proxy in route:
            proxy.deliver(event)

    def _route(self, domain: str, type_name: str) -> tuple[ConsumerProxy, ...]:
        with self._lock:
            route = tuple(
                c
                for c in self._consumers.values()
                if any(t.matches(domain, type_name) for t in c.subscribed())
            )
            if len(domain) + len(type_name) <= MAX_KEY:  # (huge names: found each time)
                if len(self._routes) >= MAX_ROUTES:
                    self._routes = {}
                self._routes[(domain, type_name)] = route
        return route

    # ---- TypeCodes --------------------------------------------------------------------------

    def _remainder(self, inp: CdrInput, at: int) -> _Remainder:
        """The TypeCode of the `any` at `at` and the generated class it names, remembered by
        the TypeCode's bytes."""
        inp.pos = at
        kind = inp.ulong()
        size = _FIXED_SIZES.get(kind, 4) if kind not in _COMPLEX else 8 + inp.length(1)
        if at + size > inp.end:
            raise MARSHAL("the event's TypeCode is truncated")
        key = (inp.e, bytes(memoryview(inp.data)[at : at + size]))
        found = self._typecodes.get(key) if size <= MAX_KEY else None
        if found is None:
            inp.pos = at
            tc = tcm.read_typecode(inp)
            found = _Remainder(tc, anys.class_for(tc), size)
            if size <= MAX_KEY:  # (a huge TypeCode is read each time, not kept)
                if len(self._typecodes) >= MAX_TYPECODES:
                    self._typecodes = {}
                self._typecodes[key] = found
        inp.pos = at + size
        return found

    def _prefix(self, domain: str, type_name: str, cls: type) -> _Prefix:
        out = event_prefix(domain, type_name)
        tc = anys.typecode_for(cls)
        tcm.write_typecode(out, tc)
        at = len(out.buf)
        p = _Prefix(bytes(out.buf), tc, at % tcm.max_alignment(tc) == 0 and not anys.has_refs(tc))
        if len(domain) + len(type_name) <= MAX_KEY:
            if len(self._prefixes) >= MAX_ROUTES:
                self._prefixes = {}
            self._prefixes[(domain, type_name, cls)] = p
        return p
