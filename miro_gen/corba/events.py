"""CORBA event channels (CosEventChannelAdmin, push model), as omniEvents and TAO serve them.

A supplier connects to a channel's ProxyPushConsumer and pushes `any` values; a consumer is a
CosEventComm::PushConsumer servant, served over IIOP, that the channel's ProxyPushSupplier
pushes them to. Values are generated types (carried with the TypeCode built from their data
schema) or plain Python values; received, an `any` becomes an instance of the generated class
with its repository id when one is importable, else plain Python data (`anys.to_python`).

    channel = EventChannel.resolve(client, "EventChannel")     # bound in the naming service
    supplier = CosEventSupplier(channel)
    supplier.push(Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(0.5, 2.0)))

    class Printer(CosEventConsumer):
        def push_event(self, value):              # on an IIOP connection's thread: be quick
            print(value)

    printer = Printer(channel)

`miro bridge corba` (miro_gen.bridges.corba) relays between such a channel and a miro-gen one.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

from miro_gen.corba.anys import read_any, write_any
from miro_gen.corba.bodies import body_input, call
from miro_gen.corba.ior import IOR, ior_from_ref, ref_from_ior
from miro_gen.exceptions import BAD_OPERATION, MARSHAL, UserException
from miro_gen.log import PeerWarnings, logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.cdrstream import CdrOutput

_log = logger("MIRO")
_peer_warnings = PeerWarnings(_log)  # what peers send: rate-limited, with counts

_ADMIN = "IDL:omg.org/CosEventChannelAdmin/"
EVENT_CHANNEL = _ADMIN + "EventChannel:1.0"
PUSH_CONSUMER = "IDL:omg.org/CosEventComm/PushConsumer:1.0"
DISCONNECTED = "IDL:omg.org/CosEventComm/Disconnected:1.0"
TIMEOUT = 10.0


class Disconnected(UserException):
    """The channel no longer takes events from this supplier (CosEventComm::Disconnected)."""

    _repo_id = DISCONNECTED


class ChannelError(UserException):
    """The channel refused a connection (AlreadyConnected, TypeError)."""

    def __init__(self, repo_id: str) -> None:
        super().__init__(repo_id)
        self.repo_id = repo_id


def _get(invoker: Any, ref: ObjectRef, operation: str) -> ObjectRef:
    """Call an operation that returns an object reference."""
    reply, inp = call(invoker, ref, operation, timeout=TIMEOUT)
    if reply.status == rpc.ReplyStatus.USER_EXCEPTION:
        raise ChannelError(reply.repo_id)
    return ref_from_ior(IOR.read(inp))


def _connect(invoker: Any, proxy: ObjectRef, operation: str, peer: ObjectRef) -> None:
    """connect_push_supplier / connect_push_consumer with `peer` (nil: none)."""
    args = CdrOutput()
    ior_from_ref(peer).write(args)
    reply, _ = call(invoker, proxy, operation, args, timeout=TIMEOUT)
    if reply.status == rpc.ReplyStatus.USER_EXCEPTION:
        raise ChannelError(reply.repo_id)


class EventChannel:
    """A CosEventChannelAdmin::EventChannel, and the IIOP invoker it is called through."""

    def __init__(self, ref: ObjectRef, invoker: Any) -> None:
        self.ref = ref
        self.invoker = invoker

    @classmethod
    def resolve(cls, client: Any, name: str = "EventChannel") -> EventChannel:
        """The channel bound as `name` in the CORBA naming service of a `Client`/`Server`
        (started with --naming of a CORBA naming service), or named by a URL (IOR, corbaloc,
        corbaname) given as `name`."""
        corba = getattr(client, "corba", None)
        if corba is None:
            raise BAD_OPERATION(
                "CORBA event channels are found through a CORBA naming service: start with "
                "--naming corbaloc:iiop:HOST:PORT/NameService"
            )
        if ":" in name:
            from miro_gen.corba.naming import resolve_url

            return cls(resolve_url(corba.iiop, name), corba.iiop)
        entry = client.naming.resolve(name)
        ref = getattr(entry, "ref", None) or ObjectRef(entry.repo_id, entry.endpoint, entry.key)
        return cls(ref, corba.iiop)

    def for_suppliers(self) -> ObjectRef:
        return _get(self.invoker, self.ref, "for_suppliers")

    def for_consumers(self) -> ObjectRef:
        return _get(self.invoker, self.ref, "for_consumers")

    def destroy(self) -> None:
        call(self.invoker, self.ref, "destroy", timeout=TIMEOUT)


class CosEventSupplier:
    """Pushes values into a channel through a ProxyPushConsumer of its own (a push supplier
    that the channel does not call back: connected as nil). `push` may be called from any
    thread; it returns when the channel has the event."""

    def __init__(self, channel: EventChannel) -> None:
        self.channel = channel
        self.invoker = channel.invoker
        self.proxy = _get(self.invoker, channel.for_suppliers(), "obtain_push_consumer")
        # No PushSupplier (nil): the channel never calls this supplier back.
        _connect(self.invoker, self.proxy, "connect_push_supplier", ObjectRef())
        self.pushed = 0

    def push(self, value: Any) -> None:
        """Push `value` (a generated type, or bool/int/float/str/bytes, or an `Any_`)."""
        args = CdrOutput()
        write_any(args, value)
        reply, _ = call(self.invoker, self.proxy, "push", args, timeout=TIMEOUT)
        if reply.status == rpc.ReplyStatus.USER_EXCEPTION:
            raise Disconnected() if reply.repo_id == DISCONNECTED else ChannelError(reply.repo_id)
        self.pushed += 1

    def close(self) -> None:
        with contextlib.suppress(Exception):  # the channel may be gone already
            call(self.invoker, self.proxy, "disconnect_push_consumer", timeout=TIMEOUT)


class CosEventConsumer(rpc.Servant):
    """A CosEventComm::PushConsumer connected to a channel: subclass it and override
    `push_event(value)`. It runs on the thread of the channel's connection, one event after
    another, in order: return quickly (hand slow work to another thread)."""

    _repo_id = PUSH_CONSUMER

    def __init__(self, channel: EventChannel) -> None:
        self.channel = channel
        self.invoker = channel.invoker
        self.received = 0
        self.undecodable = 0
        self.connected = threading.Event()
        ref = self.invoker.reference_for(self)
        self.proxy = _get(self.invoker, channel.for_consumers(), "obtain_push_supplier")
        _connect(self.invoker, self.proxy, "connect_push_consumer", ref)
        self.connected.set()

    def push_event(self, value: Any) -> None:
        """Called for each event received (override it)."""

    def disconnected(self) -> None:
        """Called when the channel disconnects this consumer (override it if it matters)."""

    @rpc.nonblocking
    def push(self, body: bytes) -> bytes:
        try:
            inp = body_input(body)
            value = read_any(inp)
        except MARSHAL as e:
            self.undecodable += 1
            _peer_warnings.warning("dropped an event that does not decode: %s", e)
            return _EMPTY
        self.received += 1
        try:
            self.push_event(value)
        except Exception:
            _log.exception("push_event failed")
        return _EMPTY

    @rpc.nonblocking
    def disconnect_push_consumer(self, body: bytes) -> bytes:
        self.connected.clear()
        self.disconnected()
        return _EMPTY

    def close(self) -> None:
        """Disconnect from the channel and stop being served."""
        if self.connected.is_set():
            with contextlib.suppress(Exception):
                call(self.invoker, self.proxy, "disconnect_push_supplier", timeout=TIMEOUT)
        self.connected.clear()
        server = getattr(self.invoker, "server", None)
        if server is not None:
            server.deactivate_servant(self)

    _dispatch = {
        "push": lambda self, body, inv: self.push(body),
        "disconnect_push_consumer": lambda self, body, inv: self.disconnect_push_consumer(body),
    }


_EMPTY = b"\x00\x01\x00\x00"
