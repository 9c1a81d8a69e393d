"""Device drivers in the manual's Publish Server and Reactor shape (§6.2, §7.5).

A *Connection* (`TtyConnection` on pyserial, `SockConnection` on TCP) owns the device and is
registered with the process reactor; bytes that arrive go to the *event handler*
(`DevEventHandler`), whose framer cuts them into *messages* (`DevMessage`: bytes and the time they
arrived) and dispatches each to the *consumer* (`DevConsumer.handle_message`), which turns it into
an IDL type and gives it to the *Implementation* (`integrate_data`). The handler and the consumer
run on the reactor thread and must not block; polled calls that wait for data run on the server's
worker pool.
"""

from miro_gen.devices.connection import Connection, SockConnection, TtyConnection
from miro_gen.devices.framers import (
    DelimitedFramer,
    FixedLengthFramer,
    Framer,
    LengthPrefixedFramer,
    LineFramer,
)
from miro_gen.devices.handler import DevConsumer, DevEventHandler, DevMessage, SubscriberNotice

__all__ = [
    "Connection",
    "DelimitedFramer",
    "DevConsumer",
    "DevEventHandler",
    "DevMessage",
    "FixedLengthFramer",
    "Framer",
    "LengthPrefixedFramer",
    "LineFramer",
    "SockConnection",
    "SubscriberNotice",
    "TtyConnection",
]
