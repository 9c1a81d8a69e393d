"""Quality of service of a notification channel, its admins and proxies (CosNotification's
QoSAdmin, AdminPropertiesAdmin): what is accepted, what it means here, what is refused.

Accepted and honoured, for the queue of each consumer the channel pushes to:

| property                | values                       | meaning here                         |
|-------------------------|------------------------------|--------------------------------------|
| `MaxEventsPerConsumer`  | 0 (`DEFAULT_DEPTH`) to MAX   | events waiting for that consumer     |
| `DiscardPolicy`         | AnyOrder, FifoOrder,         | a full queue drops the oldest (Any,  |
|                         | LifoOrder                    | Fifo) or the newest (Lifo)           |
| `OrderPolicy`           | AnyOrder, FifoOrder          | delivered in the order they came     |
| `EventReliability`,     | BestEffort                   | as the ZeroMQ door: nothing persists |
| `ConnectionReliability` |                              |                                      |
| `Priority`              | any short                    | kept; orders nothing without         |
|                         |                              | PriorityOrder (as in TAO)            |
| `StartTimeSupported`,   | FALSE                        |                                      |
| `StopTimeSupported`     |                              |                                      |

Admin properties of a channel: `MaxConsumers`, `MaxSuppliers` (0: the channel's own limits,
at most those), `MaxQueueLength` 0 and `RejectNewEvents` FALSE. Anything else, or another
value, is refused (UnsupportedQoS, UnsupportedAdmin) naming each property refused.
"""

from __future__ import annotations

from typing import Any, ClassVar

from miro_gen.corba.anys import Any_
from miro_gen.corba.notify.wire import (
    BAD_TYPE,
    QOS_ADMIN,
    UNSUPPORTED_PROPERTY,
    UNSUPPORTED_VALUE,
    UnsupportedAdmin,
    UnsupportedQoS,
    read_properties,
    short_any,
    write_properties,
)
from miro_gen.corba.servants import HandServant
from miro_gen.runtime import rpc
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

DEFAULT_DEPTH = 1000  # events a consumer's queue holds unless MaxEventsPerConsumer says
MAX_DEPTH = 100_000  # ... at most
ANY_ORDER, FIFO_ORDER, PRIORITY_ORDER, DEADLINE_ORDER, LIFO_ORDER = 0, 1, 2, 3, 4
BEST_EFFORT = 0

_SHORT_VALUES = {
    "DiscardPolicy": {ANY_ORDER, FIFO_ORDER, LIFO_ORDER},
    "OrderPolicy": {ANY_ORDER, FIFO_ORDER},
    "EventReliability": {BEST_EFFORT},
    "ConnectionReliability": {BEST_EFFORT},
}
Settings = dict[str, Any]


def _number(value: Any) -> int | None:
    value = value.value if isinstance(value, Any_) else value
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def checked_qos(props: list[tuple[str, Any]]) -> Settings:
    """The settings of QoS properties, or UnsupportedQoS naming each one refused."""
    settings: Settings = {}
    errors: list[tuple[int, str]] = []
    for name, value in props:
        number = _number(value)
        flag = value.value if isinstance(value, Any_) else value
        if name == "MaxEventsPerConsumer":
            if number is None:
                errors.append((BAD_TYPE, name))
            elif not 0 <= number <= MAX_DEPTH:
                errors.append((UNSUPPORTED_VALUE, name))
            else:
                settings[name] = number
        elif name in _SHORT_VALUES:
            if number is None:
                errors.append((BAD_TYPE, name))
            elif number not in _SHORT_VALUES[name]:
                errors.append((UNSUPPORTED_VALUE, name))
            else:
                settings[name] = number
        elif name == "Priority":
            if number is None:
                errors.append((BAD_TYPE, name))
            else:
                settings[name] = number
        elif name in ("StartTimeSupported", "StopTimeSupported"):
            if flag is not False:
                errors.append((UNSUPPORTED_VALUE, name))
        else:
            errors.append((UNSUPPORTED_PROPERTY, name))
    if errors:
        raise UnsupportedQoS(errors)
    return settings


def checked_admin(props: list[tuple[str, Any]]) -> Settings:
    """The settings of admin properties, or UnsupportedAdmin naming each one refused."""
    settings: Settings = {}
    errors: list[tuple[int, str]] = []
    for name, value in props:
        number = _number(value)
        flag = value.value if isinstance(value, Any_) else value
        if name in ("MaxConsumers", "MaxSuppliers"):
            if number is None or number < 0:
                errors.append((BAD_TYPE if number is None else UNSUPPORTED_VALUE, name))
            else:
                settings[name] = number
        elif name == "MaxQueueLength":
            if number != 0:
                errors.append((UNSUPPORTED_VALUE, name))
        elif name == "RejectNewEvents":
            if flag is not False:
                errors.append((UNSUPPORTED_VALUE, name))
        else:
            errors.append((UNSUPPORTED_PROPERTY, name))
    if errors:
        raise UnsupportedAdmin(errors)
    return settings


def as_properties(settings: Settings) -> list[tuple[str, Any]]:
    """Settings as the PropertySeq `get_qos` returns (every value a short but the depth)."""
    out: list[tuple[str, Any]] = []
    for name, value in sorted(settings.items()):
        if name in ("MaxEventsPerConsumer", "MaxConsumers", "MaxSuppliers"):
            out.append((name, int(value)))
        else:
            out.append((name, short_any(int(value))))
    return out


def depth(settings: Settings) -> int:
    """The queue depth of a consumer with these (effective) settings."""
    return int(settings.get("MaxEventsPerConsumer") or DEFAULT_DEPTH)


def drops_newest(settings: Settings) -> bool:
    """Whether a full queue drops the newest event (LifoOrder) rather than the oldest."""
    return bool(settings.get("DiscardPolicy") == LIFO_ORDER)


class QoSAdmin(HandServant):
    """CosNotification::QoSAdmin's operations on `self.qos` (see the table above)."""

    _interfaces = frozenset({QOS_ADMIN})
    _operations: ClassVar[tuple[str, ...]] = ("get_qos", "set_qos", "validate_qos")
    qos: Settings

    @rpc.nonblocking
    def get_qos(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        write_properties(out, as_properties(self.qos))
        return out

    @rpc.nonblocking
    def set_qos(self, inp: CdrInput) -> None:
        self.qos = {**self.qos, **checked_qos(read_properties(inp))}
        self.qos_changed()

    @rpc.nonblocking
    def validate_qos(self, inp: CdrInput) -> CdrOutput:
        checked_qos(read_properties(inp))
        out = CdrOutput()
        out.ulong(0)  # available_qos: no further ranges offered
        return out

    def qos_changed(self) -> None:
        """The settings changed (override to apply them)."""
