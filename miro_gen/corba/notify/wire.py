"""CosNotification on the wire: repository ids, event types, properties, the structured event,
and the exceptions the channel raises (omniORB's CosNotify*.idl, the OMG Notification Service).

A structured event is a header (domain name, type name, event name, optional header fields),
filterable fields, and `remainder_of_body`, an `any`: a TypeCode and the value it describes.
`read_head` reads what routing needs (the three names, where the `any` starts) without
decoding the value; `event_body` writes an event from its parts. Property values are `any`s
too; those of QoS settings are read with `anys.read_any`.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from miro_gen.corba import anys
from miro_gen.corba import typecode as tcm
from miro_gen.corba.servants import GiopUserException
from miro_gen.corba.typecode import K, TypeCode
from miro_gen.exceptions import MARSHAL
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

_N = "IDL:omg.org/CosNotification/"
_A = "IDL:omg.org/CosNotifyChannelAdmin/"
_C = "IDL:omg.org/CosNotifyComm/"
_F = "IDL:omg.org/CosNotifyFilter/"
_E = "IDL:omg.org/CosEventChannelAdmin/"
_EC = "IDL:omg.org/CosEventComm/"

EVENT_CHANNEL = _A + "EventChannel:1.0"
EVENT_CHANNEL_FACTORY = _A + "EventChannelFactory:1.0"
CONSUMER_ADMIN = _A + "ConsumerAdmin:1.0"
SUPPLIER_ADMIN = _A + "SupplierAdmin:1.0"
PROXY_CONSUMER = _A + "ProxyConsumer:1.0"
PROXY_SUPPLIER = _A + "ProxySupplier:1.0"
STRUCTURED_PROXY_PUSH_CONSUMER = _A + "StructuredProxyPushConsumer:1.0"
STRUCTURED_PROXY_PUSH_SUPPLIER = _A + "StructuredProxyPushSupplier:1.0"
PROXY_PUSH_CONSUMER = _A + "ProxyPushConsumer:1.0"
PROXY_PUSH_SUPPLIER = _A + "ProxyPushSupplier:1.0"
QOS_ADMIN = _N + "QoSAdmin:1.0"
ADMIN_PROPERTIES_ADMIN = _N + "AdminPropertiesAdmin:1.0"
NOTIFY_PUBLISH = _C + "NotifyPublish:1.0"
NOTIFY_SUBSCRIBE = _C + "NotifySubscribe:1.0"
STRUCTURED_PUSH_CONSUMER = _C + "StructuredPushConsumer:1.0"
STRUCTURED_PUSH_SUPPLIER = _C + "StructuredPushSupplier:1.0"
NOTIFY_PUSH_CONSUMER = _C + "PushConsumer:1.0"
NOTIFY_PUSH_SUPPLIER = _C + "PushSupplier:1.0"
FILTER = _F + "Filter:1.0"
FILTER_FACTORY = _F + "FilterFactory:1.0"
FILTER_ADMIN = _F + "FilterAdmin:1.0"
COS_EVENT_CHANNEL = _E + "EventChannel:1.0"
COS_CONSUMER_ADMIN = _E + "ConsumerAdmin:1.0"
COS_SUPPLIER_ADMIN = _E + "SupplierAdmin:1.0"
COS_PROXY_PUSH_CONSUMER = _E + "ProxyPushConsumer:1.0"
COS_PROXY_PUSH_SUPPLIER = _E + "ProxyPushSupplier:1.0"
COS_PUSH_CONSUMER = _EC + "PushConsumer:1.0"
COS_PUSH_SUPPLIER = _EC + "PushSupplier:1.0"

# CosNotifyChannelAdmin's enums
ANY_EVENT, STRUCTURED_EVENT, SEQUENCE_EVENT = 0, 1, 2  # ClientType
PUSH_ANY, PUSH_STRUCTURED = 0, 2  # ProxyType
AND_OP, OR_OP = 0, 1  # InterFilterGroupOperator
ALL_NOW_UPDATES_OFF, ALL_NOW_UPDATES_ON, NONE_NOW_UPDATES_OFF, NONE_NOW_UPDATES_ON = 0, 1, 2, 3

ANY_TYPE = "%ANY"  # the type name of an event pushed as a plain `any`
WILDCARDS = frozenset(("*", "%ALL", ""))  # a domain or type name matching any

MAX_TYPES = 1000  # event types in one offer or subscription change, and held per party
MAX_PROPERTIES = 256  # properties in one header, body or QoS list
MAX_NAME = 1024  # bytes of a domain, type or event name


class EventType(NamedTuple):
    domain_name: str
    type_name: str

    def matches(self, domain: str, type_name: str) -> bool:
        """Whether an event of (`domain`, `type_name`) is of this type (`*` matching any)."""
        return (self.domain_name in WILDCARDS or self.domain_name == domain) and (
            self.type_name in WILDCARDS or self.type_name == type_name
        )


EVERYTHING = EventType("*", "*")


def canonical(t: EventType) -> EventType:
    """The same type, its wildcards spelt `*`."""
    d = "*" if t.domain_name in WILDCARDS else t.domain_name
    n = "*" if t.type_name in WILDCARDS else t.type_name
    return t if (d, n) == t else EventType(d, n)


def read_event_types(inp: CdrInput) -> list[EventType]:
    n = inp.length(8, "event types")
    if n > MAX_TYPES:
        raise MARSHAL(f"{n} event types: at most {MAX_TYPES} at once")
    return [
        canonical(EventType(inp.string("domain name"), inp.string("type name"))) for _ in range(n)
    ]


def write_event_types(out: CdrOutput, types: list[EventType]) -> None:
    out.ulong(len(types))
    for t in types:
        out.string(t.domain_name)
        out.string(t.type_name)


# ---- properties -------------------------------------------------------------------------------


def read_properties(inp: CdrInput) -> list[tuple[str, Any]]:
    """A PropertySeq: (name, value) pairs, values as `anys.read_any` makes them."""
    n = inp.length(9, "properties")
    if n > MAX_PROPERTIES:
        raise MARSHAL(f"{n} properties: at most {MAX_PROPERTIES}")
    return [(inp.string("property name"), anys.read_any(inp)) for _ in range(n)]


def write_properties(out: CdrOutput, props: list[tuple[str, Any]]) -> None:
    out.ulong(len(props))
    for name, value in props:
        out.string(name)
        anys.write_any(out, value)


def skip_properties(inp: CdrInput) -> None:
    """Move past a PropertySeq (each value read whole, and checked)."""
    n = inp.length(9, "properties")
    if n > MAX_PROPERTIES:
        raise MARSHAL(f"{n} properties: at most {MAX_PROPERTIES}")
    for _ in range(n):
        inp.string("property name")
        anys.transcode(tcm.read_typecode(inp), inp, CdrOutput(), anys.GIOP_REFS, anys.GIOP_REFS)


def short_any(value: int) -> anys.Any_:
    return anys.Any_(tcm.simple(K.tk_short), value)


# ---- the structured event ---------------------------------------------------------------------


class EventHead(NamedTuple):
    """What routing needs of a structured event received: its names, whether it has optional
    header fields or filterable data, and where its `remainder_of_body` begins."""

    domain: str
    type_name: str
    event_name: str
    extras: bool  # optional header fields or filterable data
    body_at: int  # the position of the remainder's TypeCode


def read_head(inp: CdrInput) -> EventHead:
    domain = inp.string("domain name")
    type_name = inp.string("type name")
    event_name = inp.string("event name")
    if max(len(domain), len(type_name), len(event_name)) > MAX_NAME:
        raise MARSHAL(f"an event name is longer than {MAX_NAME} bytes")
    at = inp.pos
    extras = inp.ulong() != 0 or inp.ulong() != 0
    if extras:  # rare: read them whole, to find where the remainder begins
        inp.pos = at
        skip_properties(inp)
        skip_properties(inp)
    inp.align(4)
    return EventHead(domain, type_name, event_name, extras, inp.pos)


def event_prefix(domain: str, type_name: str, event_name: str = "") -> CdrOutput:
    """A structured event up to its `remainder_of_body`: its names, no optional header fields
    and no filterable data (what every event from the ZeroMQ door carries)."""
    out = CdrOutput()
    out.string(domain)
    out.string(type_name)
    out.string(event_name)
    out.ulong(0)
    out.ulong(0)
    return out


def _struct(name: str, members: list[tuple[str, TypeCode]]) -> TypeCode:
    return TypeCode(K.tk_struct, _N + name + ":1.0", name, members)


def _alias(name: str, content: TypeCode) -> TypeCode:
    return TypeCode(K.tk_alias, _N + name + ":1.0", name, content=content)


_STRING = tcm.string_tc()
_PROPERTY_SEQ = _alias(
    "PropertySeq",
    TypeCode(
        K.tk_sequence,
        content=_struct(
            "Property",
            [
                ("name", _alias("PropertyName", _alias("Istring", _STRING))),
                ("value", _alias("PropertyValue", tcm.simple(K.tk_any))),
            ],
        ),
    ),
)
EVENT_TYPE_TC = _struct("EventType", [("domain_name", _STRING), ("type_name", _STRING)])
STRUCTURED_EVENT_TC = _struct(
    "StructuredEvent",
    [
        (
            "header",
            _struct(
                "EventHeader",
                [
                    (
                        "fixed_header",
                        _struct(
                            "FixedEventHeader",
                            [("event_type", EVENT_TYPE_TC), ("event_name", _STRING)],
                        ),
                    ),
                    ("variable_header", _alias("OptionalHeaderFields", _PROPERTY_SEQ)),
                ],
            ),
        ),
        ("filterable_data", _alias("FilterableEventBody", _PROPERTY_SEQ)),
        ("remainder_of_body", tcm.simple(K.tk_any)),
    ],
)


def normalised(inp: CdrInput) -> bytes:
    """The structured event at `inp` laid out again little-endian from a multiple of 8 (the
    form events are forwarded in), whatever byte order and alignment it came in."""
    out = CdrOutput()
    anys.transcode(STRUCTURED_EVENT_TC, inp, out, anys.GIOP_REFS, anys.GIOP_REFS)
    return bytes(out.buf)


# ---- exceptions -------------------------------------------------------------------------------


class AlreadyConnected(GiopUserException):
    _repo_id = _E + "AlreadyConnected:1.0"


class TypeError_(GiopUserException):
    _repo_id = _E + "TypeError:1.0"


class Disconnected(GiopUserException):
    _repo_id = _EC + "Disconnected:1.0"


class AdminNotFound(GiopUserException):
    _repo_id = _A + "AdminNotFound:1.0"


class ProxyNotFound(GiopUserException):
    _repo_id = _A + "ProxyNotFound:1.0"


class ChannelNotFound(GiopUserException):
    _repo_id = _A + "ChannelNotFound:1.0"


class NotConnected(GiopUserException):
    _repo_id = _A + "NotConnected:1.0"


class ConnectionAlreadyActive(GiopUserException):
    _repo_id = _A + "ConnectionAlreadyActive:1.0"


class ConnectionAlreadyInactive(GiopUserException):
    _repo_id = _A + "ConnectionAlreadyInactive:1.0"


class FilterNotFound(GiopUserException):
    _repo_id = _F + "FilterNotFound:1.0"


class InvalidGrammar(GiopUserException):
    _repo_id = _F + "InvalidGrammar:1.0"


class ConstraintNotFound(GiopUserException):
    _repo_id = _F + "ConstraintNotFound:1.0"

    def __init__(self, ident: int) -> None:
        super().__init__(ident)
        self.ident = ident

    def write_members(self, out: CdrOutput) -> None:
        out.long(self.ident)


class InvalidConstraint(GiopUserException):
    """A constraint that does not parse: the constraint (its event types and expression)."""

    _repo_id = _F + "InvalidConstraint:1.0"

    def __init__(self, types: list[EventType], expression: str, why: str = "") -> None:
        super().__init__(expression)
        self.types = types
        self.expression = expression
        self.why = why

    def write_members(self, out: CdrOutput) -> None:
        write_event_types(out, self.types)
        out.string(self.expression)


class InvalidEventType(GiopUserException):
    _repo_id = _C + "InvalidEventType:1.0"

    def __init__(self, t: EventType) -> None:
        super().__init__(t)
        self.type = t

    def write_members(self, out: CdrOutput) -> None:
        out.string(self.type.domain_name)
        out.string(self.type.type_name)


# QoSError_code
UNSUPPORTED_PROPERTY, UNAVAILABLE_PROPERTY, UNSUPPORTED_VALUE = 0, 1, 2
BAD_PROPERTY, BAD_TYPE, BAD_VALUE = 4, 5, 6


class UnsupportedQoS(GiopUserException):
    """QoS properties refused: (error code, property name) each, with an empty range."""

    _repo_id = _N + "UnsupportedQoS:1.0"

    def __init__(self, errors: list[tuple[int, str]]) -> None:
        super().__init__(errors)
        self.errors = errors

    def write_members(self, out: CdrOutput) -> None:
        out.ulong(len(self.errors))
        for code, name in self.errors:
            out.ulong(code)
            out.string(name)
            anys.write_any(out, None)  # available_range: low_val, high_val (none given)
            anys.write_any(out, None)

    def __str__(self) -> str:
        return ", ".join(name for _, name in self.errors)


class UnsupportedAdmin(UnsupportedQoS):
    _repo_id = _N + "UnsupportedAdmin:1.0"


class AdminLimitExceeded(GiopUserException):
    """A limit of the channel (proxies, admins): its name and value."""

    _repo_id = _A + "AdminLimitExceeded:1.0"

    def __init__(self, name: str, value: int) -> None:
        super().__init__(name)
        self.name = name
        self.value = value

    def write_members(self, out: CdrOutput) -> None:
        out.string(self.name)
        anys.write_any(out, self.value)
