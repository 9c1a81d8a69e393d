"""The Notification door's CORBA side on its own (miro_gen.corba.notify), over real IIOP
connections in one process: a channel served by an IIOPServer, called as a CORBA client calls
it, pushing to consumer servants it calls back. What Miro's tools use beyond the C++ tests of
test_corba_notify.py: filters and their constraint forms, QoS accepted and refused, consumer
queues, admins and proxies listed and bounded, and what bad clients do (malformed events,
consumers that vanish).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from typing import Any, ClassVar

import Miro
import pytest
from loopback import eventually

from miro_gen.corba import anys
from miro_gen.corba import typecode as tcm
from miro_gen.corba.bodies import call
from miro_gen.corba.client import IIOPInvoker
from miro_gen.corba.ior import IOR, ref_from_ior
from miro_gen.corba.notify import ChannelCore, EventChannelFactory, NotifyChannel, wire
from miro_gen.corba.notify.delivery import MAX_FAILURES
from miro_gen.corba.servants import HandServant
from miro_gen.corba.server import IIOPServer
from miro_gen.corba.typecode import K, TypeCode
from miro_gen.exceptions import (
    BAD_PARAM,
    MARSHAL,
    NO_IMPLEMENT,
    NO_PERMISSION,
    OBJECT_NOT_EXIST,
)
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

WAIT = 20.0


class Published:
    """A backbone that keeps what the hub publishes (the hub's side of the other door)."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str, type, bytes]] = []

    def wants(self, domain: str, type_name: str) -> bool:
        return True

    def publish(self, source: int, domain: str, type_name: str, cls: type, payload: bytes) -> None:
        self.events.append((domain, type_name, cls, payload))

    def release(self, source: int) -> None:
        pass

    def want(self, types: frozenset[wire.EventType]) -> None:
        pass

    def subscriptions(self) -> frozenset[wire.EventType]:
        return frozenset({wire.EventType("zmq", "Odometry")})

    def offers(self) -> frozenset[wire.EventType]:
        return frozenset()


class Rig:
    def __init__(self) -> None:
        self.invoker = IIOPInvoker(None)
        self.server = IIOPServer(self.invoker)
        self.invoker.server = self.server
        self.backbone = Published()
        core = ChannelCore("robot1/EventChannel", self.server, self.invoker, b"ch", self.backbone)
        self.channel = NotifyChannel(core)
        self.ref = ref_from_ior(self.channel.reference())

    def call(
        self, ref: ObjectRef, op: str, write: Callable[[CdrOutput], None] | None = None
    ) -> Any:
        """Call `op` on `ref`; the reply's stream, or the user exception's repository id."""
        out = None
        if write is not None:
            out = CdrOutput()
            write(out)
        reply, inp = call(self.invoker, ref, op, out)
        if reply.status == rpc.ReplyStatus.USER_EXCEPTION:
            return reply.repo_id
        return inp

    def get(
        self, ref: ObjectRef, op: str, write: Callable[[CdrOutput], None] | None = None
    ) -> ObjectRef:
        inp = self.call(ref, op, write)
        assert isinstance(inp, CdrInput), inp
        return ref_from_ior(IOR.read(inp))

    def close(self) -> None:
        self.channel.close()
        self.server.close()
        self.invoker.close()


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    try:
        yield r
    finally:
        r.close()


def ulong(v: int) -> Callable[[CdrOutput], None]:
    return lambda out: out.ulong(v)


def types(*pairs: tuple[str, str]) -> list[wire.EventType]:
    return [wire.EventType(d, t) for d, t in pairs]


def changes(
    added: list[wire.EventType], removed: list[wire.EventType]
) -> Callable[[CdrOutput], None]:
    def write(out: CdrOutput) -> None:
        wire.write_event_types(out, added)
        wire.write_event_types(out, removed)

    return write


def event(
    domain: str, type_name: str, value: Any, event_name: str = ""
) -> Callable[[CdrOutput], None]:
    def write(out: CdrOutput) -> None:
        prefix = wire.event_prefix(domain, type_name, event_name)
        out.raw(prefix.buf)
        anys.write_any(out, value)

    return write


class Consumer(HandServant):
    """A CosNotifyComm::StructuredPushConsumer in Python: keeps the events' names and values."""

    _repo_id = wire.STRUCTURED_PUSH_CONSUMER
    _operations: ClassVar[tuple[str, ...]] = (
        "push_structured_event", "offer_change", "disconnect_structured_push_consumer",
    )  # fmt: skip

    def __init__(self) -> None:
        self.events: list[tuple[str, str, Any]] = []
        self.offers: list[tuple[list[wire.EventType], list[wire.EventType]]] = []
        self.cond = threading.Condition()
        self.gate = threading.Event()
        self.gate.set()

    def push_structured_event(self, inp: CdrInput) -> None:
        self.gate.wait(WAIT)
        head = wire.read_head(inp)
        inp.pos = head.body_at
        value = anys.read_any(inp)
        with self.cond:
            self.events.append((head.domain, head.type_name, value))
            self.cond.notify_all()

    def offer_change(self, inp: CdrInput) -> None:
        with self.cond:
            self.offers.append((wire.read_event_types(inp), wire.read_event_types(inp)))
            self.cond.notify_all()

    def disconnect_structured_push_consumer(self, inp: CdrInput) -> None:
        pass

    def wait(self, n: int) -> list[tuple[str, str, Any]]:
        with self.cond:
            assert self.cond.wait_for(lambda: len(self.events) >= n, WAIT), self.events
            return list(self.events)


class Supplier(HandServant):
    """A CosNotifyComm::StructuredPushSupplier in Python: keeps the subscription changes."""

    _repo_id = wire.STRUCTURED_PUSH_SUPPLIER
    _operations: ClassVar[tuple[str, ...]] = (
        "subscription_change", "disconnect_structured_push_supplier",
    )  # fmt: skip

    def __init__(self) -> None:
        self.changes: list[tuple[list[wire.EventType], list[wire.EventType]]] = []
        self.cond = threading.Condition()

    def subscription_change(self, inp: CdrInput) -> None:
        with self.cond:
            self.changes.append((wire.read_event_types(inp), wire.read_event_types(inp)))
            self.cond.notify_all()

    def disconnect_structured_push_supplier(self, inp: CdrInput) -> None:
        pass


def connect_consumer(
    r: Rig, consumer: Consumer, subscriptions: list[wire.EventType] | None = None, op: int = 1
) -> tuple[ObjectRef, ObjectRef]:
    """A consumer admin of its own (OR_OP by default), a structured proxy, subscriptions set,
    connected: (admin, proxy)."""
    inp = r.call(r.ref, "new_for_consumers", ulong(op))
    admin = ref_from_ior(IOR.read(inp))
    proxy = r.get(admin, "obtain_notification_push_supplier", ulong(wire.STRUCTURED_EVENT))
    if subscriptions is not None:
        assert isinstance(
            r.call(admin, "subscription_change", changes(subscriptions, [wire.EVERYTHING])),
            CdrInput,
        )
    r.call(
        proxy,
        "connect_structured_push_consumer",
        lambda out: r.server.reference_for(consumer).ior.write(out),
    )
    return admin, proxy


def connect_supplier(r: Rig, supplier: Supplier | None = None) -> tuple[ObjectRef, ObjectRef]:
    inp = r.call(r.ref, "new_for_suppliers", ulong(wire.OR_OP))
    admin = ref_from_ior(IOR.read(inp))
    proxy = r.get(admin, "obtain_notification_push_consumer", ulong(wire.STRUCTURED_EVENT))
    ior = r.server.reference_for(supplier).ior if supplier is not None else IOR()
    assert isinstance(r.call(proxy, "connect_structured_push_supplier", ior.write), CdrInput)
    return admin, proxy


def push(r: Rig, proxy: ObjectRef, domain: str, type_name: str, value: Any, name: str = "") -> Any:
    return r.call(proxy, "push_structured_event", event(domain, type_name, value, name))


# ---- subscriptions, offers --------------------------------------------------------------------


def test_consumers_get_what_they_subscribe_to_and_suppliers_hear_of_it(rig: Rig) -> None:
    supplier = Supplier()
    _, pc = connect_supplier(rig, supplier)
    gps, everything = Consumer(), Consumer()
    connect_consumer(rig, gps, types(("robot1", "Gps")))
    connect_consumer(rig, everything)
    for domain, type_name in (("robot1", "Gps"), ("robot1", "Laser"), ("robot2", "Gps")):
        push(rig, pc, domain, type_name, Miro.TimeIDL(1, 2))
    assert [(d, t) for d, t, _ in everything.wait(3)] == [
        ("robot1", "Gps"), ("robot1", "Laser"), ("robot2", "Gps"),
    ]  # fmt: skip
    assert gps.wait(1) == [("robot1", "Gps", Miro.TimeIDL(1, 2))]
    inp = rig.call(pc, "obtain_subscription_types", ulong(wire.ALL_NOW_UPDATES_ON))
    seen = set(wire.read_event_types(inp))
    assert {wire.EventType("robot1", "Gps"), wire.EVERYTHING} <= seen
    assert wire.EventType("zmq", "Odometry") in seen  # the other door's consumers
    late = Consumer()
    connect_consumer(rig, late, types(("robot3", "Stall")))
    with supplier.cond:
        assert supplier.cond.wait_for(
            lambda: any(wire.EventType("robot3", "Stall") in a for a, _ in supplier.changes), WAIT
        ), supplier.changes


def test_offers_reach_consumers(rig: Rig) -> None:
    consumer = Consumer()
    _, proxy = connect_consumer(rig, consumer, types(("robot1", "Gps")))
    sa, _ = connect_supplier(rig)
    rig.call(sa, "offer_change", changes(types(("robot1", "Gps")), []))
    with consumer.cond:
        assert consumer.cond.wait_for(lambda: consumer.offers, WAIT)
    assert consumer.offers[0][0] == types(("robot1", "Gps"))
    inp = rig.call(proxy, "obtain_offered_types", ulong(wire.ALL_NOW_UPDATES_OFF))
    assert wire.read_event_types(inp) == types(("robot1", "Gps"))


# ---- filters ----------------------------------------------------------------------------------


def constraints(*items: tuple[list[wire.EventType], str]) -> Callable[[CdrOutput], None]:
    def write(out: CdrOutput) -> None:
        out.ulong(len(items))
        for t, expr in items:
            wire.write_event_types(out, t)
            out.string(expr)

    return write


def test_filters_with_the_constraints_miro_tools_write(rig: Rig) -> None:
    factory = rig.get(rig.ref, "_get_default_filter_factory")
    assert rig.call(factory, "create_filter", lambda out: out.string("XPATH")).endswith(
        "InvalidGrammar:1.0"
    )
    f = rig.get(factory, "create_filter", lambda out: out.string("EXTENDED_TCL"))
    bad = rig.call(f, "add_constraints", constraints(([], "$type_name ==")))
    assert bad.endswith("InvalidConstraint:1.0")
    inp = rig.call(
        f,
        "add_constraints",
        constraints(
            ([], "$domain_name == 'robot1' and ($type_name == 'Gps' or $type_name == 'Laser')"),
            (types(("robot2", "*")), "TRUE"),
        ),
    )
    assert inp.ulong() == 2
    consumer = Consumer()
    admin, proxy = connect_consumer(rig, consumer, op=wire.AND_OP)
    inp = rig.call(proxy, "add_filter", f.ior.write)  # type: ignore[attr-defined]
    assert isinstance(inp, CdrInput)
    _, pc = connect_supplier(rig)
    sent = [("robot1", "Gps"), ("robot1", "Odometry"), ("robot2", "Stall"), ("robot3", "Gps"),
            ("robot1", "Laser")]  # fmt: skip
    for d, t in sent:
        push(rig, pc, d, t, 1)
    assert [(d, t) for d, t, _ in consumer.wait(3)] == [
        ("robot1", "Gps"), ("robot2", "Stall"), ("robot1", "Laser"),
    ]  # fmt: skip
    matched = rig.call(f, "match_structured", event("robot1", "Gps", 0))
    assert matched.boolean() is True
    matched = rig.call(f, "match_structured", event("robot1", "Odometry", 0))
    assert matched.boolean() is False
    with pytest.raises(BAD_PARAM):  # a filter not of this channel's factory
        rig.call(admin, "add_filter", lambda out: IOR().write(out))


# ---- QoS and queues ----------------------------------------------------------------------------


def qos(*props: tuple[str, Any]) -> Callable[[CdrOutput], None]:
    return lambda out: wire.write_properties(out, list(props))


def test_qos_miro_sets_is_taken_and_the_rest_refused_by_name(rig: Rig) -> None:
    ok = rig.call(
        rig.ref, "set_qos",
        qos(("MaxEventsPerConsumer", 5), ("DiscardPolicy", wire.short_any(1)),
            ("OrderPolicy", wire.short_any(1)), ("EventReliability", wire.short_any(0))),
    )  # fmt: skip
    assert isinstance(ok, CdrInput)
    got = dict(wire.read_properties(rig.call(rig.ref, "get_qos")))
    assert got["MaxEventsPerConsumer"] == 5
    refused = rig.call(
        rig.ref, "set_qos", qos(("PacingInterval", 10), ("OrderPolicy", wire.short_any(2)))
    )
    assert refused.endswith("UnsupportedQoS:1.0")
    assert dict(wire.read_properties(rig.call(rig.ref, "get_qos"))) == got  # unchanged
    assert rig.call(rig.ref, "set_admin", qos(("MaxQueueLength", 5))).endswith(
        "UnsupportedAdmin:1.0"
    )


def test_a_slow_consumer_keeps_its_newest_events_and_slows_no_one(rig: Rig) -> None:
    slow, quick = Consumer(), Consumer()
    slow.gate.clear()  # its first push waits until the gate opens
    _, slow_proxy = connect_consumer(rig, slow)
    rig.call(slow_proxy, "set_qos", qos(("MaxEventsPerConsumer", 3)))
    connect_consumer(rig, quick)
    _, pc = connect_supplier(rig)
    for i in range(10):
        push(rig, pc, "robot1", "Count", i)
    assert [v for _, _, v in quick.wait(10)] == list(range(10))
    slow.gate.set()
    values = [v for _, _, v in slow.wait(4)]
    assert values == [0, 7, 8, 9]  # the one in flight, then the newest three


# ---- admins, proxies, limits -------------------------------------------------------------------


def ids(inp: CdrInput) -> list[int]:
    return [inp.long() for _ in range(inp.ulong())]


def test_admins_and_proxies_are_listed_found_and_destroyed(rig: Rig) -> None:
    consumer = Consumer()
    admin, proxy = connect_consumer(rig, consumer)
    my_id = rig.call(admin, "_get_MyID").long()
    assert ids(rig.call(rig.ref, "get_all_consumeradmins")) == [0, my_id]
    proxies = ids(rig.call(admin, "_get_push_suppliers"))
    assert len(proxies) == 1
    assert rig.get(admin, "get_proxy_supplier", lambda out: out.long(proxies[0])) == proxy
    assert rig.call(admin, "get_proxy_supplier", lambda out: out.long(999)).endswith(
        "ProxyNotFound:1.0"
    )
    assert rig.call(rig.ref, "get_consumeradmin", lambda out: out.long(999)).endswith(
        "AdminNotFound:1.0"
    )
    nil = rig.call(proxy, "connect_structured_push_consumer", lambda out: IOR().write(out))
    assert nil.endswith("TypeError:1.0")
    rig.call(admin, "destroy")
    assert ids(rig.call(rig.ref, "get_all_consumeradmins")) == [0]
    with pytest.raises(OBJECT_NOT_EXIST):
        rig.call(admin, "_get_MyID")
    default = rig.get(rig.ref, "_get_default_consumer_admin")
    with pytest.raises(NO_IMPLEMENT):
        rig.call(default, "obtain_notification_push_supplier", ulong(wire.SEQUENCE_EVENT))


def test_the_limits_clients_set_are_kept(rig: Rig) -> None:
    rig.call(rig.ref, "set_admin", qos(("MaxConsumers", 1)))
    connect_consumer(rig, Consumer())
    admin = rig.get(rig.ref, "_get_default_consumer_admin")
    proxy = rig.get(admin, "obtain_notification_push_supplier", ulong(wire.STRUCTURED_EVENT))
    refused = rig.call(
        proxy, "connect_structured_push_consumer",
        lambda out: rig.server.reference_for(Consumer()).ior.write(out),
    )  # fmt: skip
    assert refused.endswith("AdminLimitExceeded:1.0")


# ---- what bad peers do --------------------------------------------------------------------------


def test_a_malformed_event_is_refused_and_the_channel_goes_on(rig: Rig) -> None:
    consumer = Consumer()
    connect_consumer(rig, consumer)
    _, pc = connect_supplier(rig)
    for garbage in (b"", b"\x05\x00\x00\x00ab", b"\x00" * 12 + b"\xff\xff\xff\xff" * 3):
        with pytest.raises(MARSHAL):  # the supplier is told
            rig.call(pc, "push_structured_event", lambda out, g=garbage: out.raw(g))
    assert rig.channel.hub.malformed == 3
    push(rig, pc, "robot1", "Gps", 7)
    assert consumer.wait(1) == [("robot1", "Gps", 7)]


def test_an_unknown_type_reaches_corba_consumers_and_is_counted(rig: Rig) -> None:
    consumer = Consumer()
    connect_consumer(rig, consumer)
    _, pc = connect_supplier(rig)
    strange = TypeCode(K.tk_struct, "IDL:Elsewhere/Strange:1.0", "Strange",
                       [("x", tcm.simple(K.tk_long))])  # fmt: skip
    push(rig, pc, "robot1", "Strange", anys.Any_(strange, {"x": 5}))
    push(rig, pc, "robot1", "Time", Miro.TimeIDL(3, 4))
    got = consumer.wait(2)
    assert got[0][2] == anys.Any_(strange, {"x": 5}) or got[0][2] == {"x": 5}
    assert rig.channel.hub.unknown == 1
    published = [(d, t) for d, t, _, _ in rig.backbone.events]
    assert published == [("robot1", "Time")]  # the unknown one stays on the CORBA side
    cls, payload = rig.backbone.events[0][2:]
    assert cls.deserialize(payload) == Miro.TimeIDL(3, 4)


def test_a_vanished_consumer_is_dropped_after_a_few_pushes(rig: Rig) -> None:
    gone, alive = Consumer(), Consumer()
    _, proxy = connect_consumer(rig, gone)
    connect_consumer(rig, alive)
    rig.server.deactivate_servant(gone)  # its process died: OBJECT_NOT_EXIST
    _, pc = connect_supplier(rig)
    for i in range(MAX_FAILURES + 5):
        push(rig, pc, "robot1", "Count", i)
    assert [v for _, _, v in alive.wait(MAX_FAILURES + 5)] == list(range(MAX_FAILURES + 5))
    eventually(
        lambda: rig.channel.core.consumers <= 1,
        WAIT,
        lambda: "the vanished consumer was never dropped",
    )
    with pytest.raises(OBJECT_NOT_EXIST):  # its proxy is destroyed
        rig.call(proxy, "_get_MyType")
    with pytest.raises(MARSHAL):
        rig.call(pc, "obtain_subscription_types", lambda out: None)


def test_the_factory_lists_makes_and_destroys_channels(rig: Rig) -> None:
    made: list[NotifyChannel] = []

    def maker(qos: dict[str, Any], admin: dict[str, Any]) -> NotifyChannel:
        core = ChannelCore(f"made{len(made)}", rig.server, rig.invoker, f"m{len(made)}".encode())
        channel = NotifyChannel(core, destroyable=True)
        made.append(channel)
        return channel

    factory = EventChannelFactory(
        lambda: rig.server.ior(b"factory", wire.EVENT_CHANNEL_FACTORY), maker
    )
    rig.server.activate(factory, b"factory")
    factory.add(rig.channel)
    fref = ref_from_ior(factory.reference())
    assert ids(rig.call(fref, "get_all_channels")) == [1]
    refused = rig.call(fref, "create_channel", lambda out: (
        wire.write_properties(out, [("PacingInterval", 5)]), wire.write_properties(out, [])
    ))  # fmt: skip
    assert refused.endswith("UnsupportedQoS:1.0") and not made
    inp = rig.call(fref, "create_channel", lambda out: (out.ulong(0), out.ulong(0)))
    new = ref_from_ior(IOR.read(inp))
    assert inp.long() == 2 and ids(rig.call(fref, "get_all_channels")) == [1, 2]
    assert rig.get(new, "_get_MyFactory") == fref
    rig.call(new, "destroy")
    assert ids(rig.call(fref, "get_all_channels")) == [1]
    assert rig.call(fref, "get_event_channel", lambda out: out.long(2)).endswith(
        "ChannelNotFound:1.0"
    )
    with pytest.raises(NO_PERMISSION):  # the hosted channel is its process's to destroy
        rig.call(rig.ref, "destroy")


def test_any_events_and_cosevent_clients_share_the_channel(rig: Rig) -> None:
    from miro_gen.corba.events import CosEventConsumer, CosEventSupplier, EventChannel

    structured = Consumer()
    connect_consumer(rig, structured)
    got: list[Any] = []
    arrived = threading.Event()

    class Plain(CosEventConsumer):
        def push_event(self, value: Any) -> None:
            got.append(value)
            arrived.set()

    channel = EventChannel(rig.ref, rig.invoker)
    plain = Plain(channel)  # CosEventChannelAdmin: for_consumers, obtain_push_supplier
    CosEventSupplier(channel).push(Miro.TimeIDL(5, 6))  # ... for_suppliers, obtain_push_consumer
    assert structured.wait(1) == [("", "%ANY", Miro.TimeIDL(5, 6))]  # an `any` event: type %ANY
    assert arrived.wait(WAIT) and got == [Miro.TimeIDL(5, 6)]  # as it came
    admin = rig.get(rig.ref, "_get_default_supplier_admin")
    proxy = rig.get(admin, "obtain_notification_push_consumer", ulong(wire.ANY_EVENT))
    assert rig.call(proxy, "_get_MyType").ulong() == wire.PUSH_ANY
    rig.call(proxy, "connect_any_push_supplier", lambda out: IOR().write(out))
    rig.call(proxy, "push", lambda out: anys.write_any(out, 42))
    assert structured.wait(2)[1] == ("", "%ANY", 42)
    _, pc = connect_supplier(rig)
    push(rig, pc, "robot1", "Time", Miro.TimeIDL(7, 8))
    arrived.clear()
    while len(got) < 3:  # a structured event reaches an `any` consumer as a StructuredEvent
        assert arrived.wait(WAIT)
        arrived.clear()
    assert got[1] == 42 and isinstance(got[2], dict)
    header = got[2]["header"]["fixed_header"]
    assert header["event_type"] == {"domain_name": "robot1", "type_name": "Time"}
    plain.close()


def test_no_request_body_makes_a_servant_fail(rig: Rig) -> None:
    """Every operation of every kind of object, given random bodies: refused with MARSHAL,
    BAD_PARAM or an IDL exception, never UNKNOWN (a defect of ours), and the channel goes on."""
    import random

    from miro_gen.exceptions import UNKNOWN, SystemException

    consumer = Consumer()
    admin, proxy = connect_consumer(rig, consumer)
    sadmin, pc = connect_supplier(rig)
    factory = rig.get(rig.ref, "_get_default_filter_factory")
    f = rig.get(factory, "create_filter", lambda out: out.string("EXTENDED_TCL"))
    objects = {
        rig.ref: rig.channel.servant, admin: None, proxy: None, sadmin: None, pc: None,
        factory: None, f: None,
    }  # fmt: skip
    rng = random.Random(27)
    for ref in objects:
        servant = rig.server._servant(ref.key)
        assert servant is not None
        for op in sorted(servant._dispatch):
            if op.startswith(("disconnect", "suspend")) or op == "destroy":
                continue
            for _ in range(20):
                body = rng.randbytes(rng.choice((0, 3, 8, 40, 200)))
                try:
                    rig.call(ref, op, lambda out, b=body: out.raw(b))
                except UNKNOWN as e:
                    pytest.fail(f"{op}: {e}")
                except SystemException:
                    pass
    push(rig, pc, "robot1", "Gps", 9)
    assert consumer.wait(1)[-1] == ("robot1", "Gps", 9)
