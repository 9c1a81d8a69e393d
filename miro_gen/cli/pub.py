"""`miro pub [DOMAIN/]TYPE VALUE`: publish an event by hand (the manual's NotifyObserver), with
no generated code here: the payload's type is the one the running suppliers of TYPE offer
(their service gives its data schema, compiled once and cached), or `--payload`."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from typing import Any

from miro_gen.cli.liveargs import connect
from miro_gen.live.remote import LiveError, Robot

SUBSCRIBER_WAIT = 2.0  # seconds a single event waits for a subscriber to appear


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro pub",
        description="Publish an event of TYPE (a structured event's type name, ExampleEvent) "
        "with VALUE (YAML or JSON: {counter: 1, data: {a: 1, b: 2}}; - reads it from the "
        "standard input) as its payload, once or RATE times a second. The payload's type is "
        "the one the running suppliers of TYPE offer, else --payload. Accepts the common "
        "options (--naming tcp://HOST:PORT, -MNC NAME: the default domain).",
    )
    p.add_argument("topic", metavar="[DOMAIN/]TYPE", help="the event's type name, with its domain")
    p.add_argument("value", metavar="VALUE", help="the payload, as YAML or JSON")
    p.add_argument("--payload", metavar="IDLTYPE", help="the payload's IDL type (Miro::GpsDataIDL)")
    p.add_argument("--channel", metavar="NAME", help="the event channel (default: the offer's)")
    p.add_argument("-r", "--rate", type=float, default=0, metavar="HZ", help="events per second")
    p.add_argument(
        "-n",
        "--count",
        type=int,
        default=0,
        help="events to publish (default: 1, or with --rate until Ctrl-C)",
    )
    return p


def pub_main(argv: Sequence[str]) -> int:
    p = parser()
    robot, ns = connect(p, "miro pub", argv)
    if ns.rate < 0 or ns.count < 0:
        p.error("--rate and --count must be 0 or more")
    count = ns.count or (0 if ns.rate else 1)
    domain, _, type_name = ns.topic.rpartition("/")
    domain = domain or robot.options.naming_context
    if not type_name or "*" in ns.topic:
        p.error(f"{ns.topic!r} is not [DOMAIN/]TYPE")
    try:
        cls, channel_name = _payload(robot, domain, type_name, ns.payload)
        payload = _value(cls, ns.value)
    except LiveError as e:
        print(f"miro pub: {e}", file=sys.stderr)
        return 1
    finally:
        robot.close()
    return _publish(argv, domain, type_name, payload, ns.channel or channel_name, ns.rate, count)


def _payload(robot: Robot, domain: str, type_name: str, given: str | None) -> tuple[Any, str]:
    """The payload class, and the channel the offer is on ('EventChannel' without one)."""
    from miro_gen.live.schemas import SchemaError, compile_schema, data_class

    offers = [
        (s, o)
        for s in robot.services()
        if s.description is not None
        for o in s.description.offers
        if o.type_name == type_name and (given is None or o.payload == given)
    ]
    exact = [(s, o) for s, o in offers if o.domain == domain]
    chosen = (exact or offers)[:1]
    if chosen:
        service, offer = chosen[0]
        import MiroService

        from miro_gen.exceptions import SystemException

        try:
            text = robot.service_at(service.entry.endpoint).type_schema(offer.type_hash)
            return data_class(compile_schema(text), offer.payload), offer.channel
        except (MiroService.NotFound, SystemException, SchemaError) as e:
            raise LiveError(f"the type of {type_name} from {service.name}: {e}") from None
    if given is None:
        raise LiveError(
            f"nobody publishes {type_name} now, so its payload type is unknown: give it "
            "with --payload (Miro::GpsDataIDL)"
        )
    cls = _local_type(given)
    if cls is None:
        raise LiveError(f"no running service publishes {given}, and it is not compiled here")
    return cls, "EventChannel"


def _local_type(scoped: str) -> Any:
    """A generated class of this name on this machine's path."""
    from miro_gen.runtime import registry

    registry.discover()
    for cls in registry.known_types():
        if cls._type_name == scoped:
            return cls
    return None


def _value(cls: Any, text: str) -> Any:
    import yaml

    from miro_gen.live.values import from_plain

    if text == "-":
        text = sys.stdin.read()
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise LiveError(f"cannot read the value: {getattr(e, 'problem', e)}") from None
    try:
        return from_plain(cls, {} if data is None else data, "value")
    except ValueError as e:
        raise LiveError(str(e)) from None


def _publish(
    argv: Sequence[str],
    domain: str,
    type_name: str,
    payload: Any,
    channel_name: str,
    rate: float,
    count: int,
) -> int:
    from miro_gen.cli.eventargs import make_server, resolve_or_wait
    from miro_gen.transport.events import StructuredPushSupplier

    server = make_server(parser(), "miro pub", argv)
    try:
        channel = resolve_or_wait(server, channel_name, "miro pub")
    except KeyboardInterrupt:
        server.close()
        return 0
    supplier = StructuredPushSupplier(channel, domain_name=domain)
    sent = [0]
    topic = f"{domain}/{type_name}"

    delivered = [0]

    def push(_: object = None) -> None:
        if supplier.push(type_name, payload):
            delivered[0] += 1
            print(f"published {topic} #{sent[0]}", flush=True)
        else:
            print(f"{topic} #{sent[0]}: nobody subscribes, not sent", flush=True)
        sent[0] += 1
        if count and sent[0] >= count:
            server.shutdown()

    reactor = server.reactor()
    if rate:
        reactor.schedule_timer(0.0, 1.0 / rate, push)
    else:

        def when_subscribed(_: object = None) -> None:
            if supplier.has_subscribers(type_name) or time.monotonic() >= give_up:
                reactor.cancel_timer(waiting)
                push()

        give_up = time.monotonic() + SUBSCRIBER_WAIT
        waiting = reactor.schedule_timer(0.0, 0.02, when_subscribed)
    server.run()
    return 0 if delivered[0] or count != 1 else 1
