"""miro-gen: Miro (Middleware for Robots) in Python.

The IDL compiler lives in `miro_gen.idl` (`miro-idl`); generated code uses `miro_gen.runtime`;
remote-call exceptions are in `miro_gen.exceptions`. The runtime's public names are importable
from here (`from miro_gen import Server, Client`); they load the transport (and ZeroMQ) on first
use, so the compilers start without it, and `miro_gen.lifecycle`, which a service imports
first, at once.
"""

from typing import TYPE_CHECKING, Any

from miro_gen.exceptions import (
    BAD_OPERATION,
    BAD_PARAM,
    COMM_FAILURE,
    MARSHAL,
    NO_IMPLEMENT,
    NO_PERMISSION,
    NO_RESOURCES,
    OBJECT_NOT_EXIST,
    TIMEOUT,
    TRANSIENT,
    UNKNOWN,
    ActionableError,
    CompletionStatus,
    SystemException,
    UserException,
)

if TYPE_CHECKING:
    from miro_gen.runtime.rpc import nonblocking
    from miro_gen.service.implementation import Implementation
    from miro_gen.service.server import Client, Server
    from miro_gen.transport.events import (
        KEEP_ALL,
        EventChannelFactory,
        StructuredEvent,
        StructuredPushConsumer,
        StructuredPushSupplier,
    )

__version__ = "0.1.0"

_EVENTS = "miro_gen.transport.events"
_LAZY = {
    "nonblocking": "miro_gen.runtime.rpc",
    "Server": "miro_gen.service.server",
    "Client": "miro_gen.service.server",
    "EventChannelFactory": _EVENTS,
    "StructuredPushSupplier": _EVENTS,
    "StructuredPushConsumer": _EVENTS,
    "StructuredEvent": _EVENTS,
    "KEEP_ALL": _EVENTS,  # a consumer's depth: every event kept for its handler
    "Implementation": "miro_gen.service.implementation",
}

__all__ = [
    "BAD_OPERATION",
    "BAD_PARAM",
    "COMM_FAILURE",
    "KEEP_ALL",
    "MARSHAL",
    "NO_IMPLEMENT",
    "NO_PERMISSION",
    "NO_RESOURCES",
    "OBJECT_NOT_EXIST",
    "TIMEOUT",
    "TRANSIENT",
    "UNKNOWN",
    "ActionableError",
    "Client",
    "CompletionStatus",
    "EventChannelFactory",
    "Implementation",
    "Server",
    "StructuredEvent",
    "StructuredPushConsumer",
    "StructuredPushSupplier",
    "SystemException",
    "UserException",
    "nonblocking",
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'miro_gen' has no attribute {name!r}")
