"""`miro pub [DOMAIN/]TYPE VALUE`: publish an event by hand (the manual's NotifyObserver), with
no generated code here: the payload's type is the one the running suppliers of TYPE offer
(their service gives its data schema, compiled once and cached), or `--payload`."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from miro_gen.cli.live_ros2 import add_ros2_flag, wants_ros2
from miro_gen.cli.liveargs import connect
from miro_gen.live.remote import LiveError, Robot

MAX_WAIT = 10.0  # seconds the first event waits for its subscribers, by default


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
    p.add_argument(
        "-w",
        "--wait-matching-subscriptions",
        "--wait-matching",
        dest="wait_matching",
        type=int,
        metavar="N",
        help="before the first event, wait until N consumers subscribe to it (default: 1 when "
        "the events are counted, one or --count, so that each reaches a consumer already "
        "listening; 0 with --rate until Ctrl-C)",
    )
    p.add_argument(
        "--max-wait",
        type=float,
        default=MAX_WAIT,
        metavar="S",
        help=f"wait that long at most, then publish anyway (default {MAX_WAIT:g} s; 0: no limit)",
    )
    add_ros2_flag(p, "pub")
    return p


def pub_main(argv: Sequence[str]) -> int:
    if wants_ros2(argv):
        from miro_gen.cli import live_ros2

        return live_ros2.pub_main(argv)
    p = parser()
    robot, ns = connect(p, "miro pub", argv)
    if ns.rate < 0 or ns.count < 0 or ns.max_wait < 0 or (ns.wait_matching or 0) < 0:
        p.error("--rate, --count, --wait-matching and --max-wait must be 0 or more")
    count = ns.count or (0 if ns.rate else 1)
    wanted = ns.wait_matching if ns.wait_matching is not None else (1 if count else 0)
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
    channel_name = ns.channel or channel_name
    wait = Wait(wanted, ns.max_wait)
    return _publish(argv, domain, type_name, payload, channel_name, ns.rate, count, wait)


def _payload(robot: Robot, domain: str, type_name: str, given: str | None) -> tuple[Any, str]:
    """The payload class, and the channel the offer is on ('EventChannel' without one)."""
    from miro_gen.live.schemas import SchemaError, compile_schema, data_class

    offers = [
        (s, o) for s, o in robot.offers([("*", type_name)]) if given is None or o.payload == given
    ]
    exact = [(s, o) for s, o in offers if o.domain == domain]
    chosen = (exact or offers)[:1]
    if chosen:
        service, offer = chosen[0]
        text = robot.data_schema(service, offer.type_hash)
        try:
            return data_class(compile_schema(text), offer.payload), offer.channel
        except SchemaError as e:
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
    from miro_gen.live.values import from_text

    try:
        return from_text(cls, text)
    except ValueError as e:
        raise LiveError(str(e)) from None


@dataclass
class Wait:
    """What the first event waits for: `subscriptions` matching it, at most `limit` seconds
    (0: no limit)."""

    subscriptions: int
    limit: float


def _publish(
    argv: Sequence[str],
    domain: str,
    type_name: str,
    payload: Any,
    channel_name: str,
    rate: float,
    count: int,
    wait: Wait,
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

    def begin() -> None:
        if rate:
            reactor.schedule_timer(0.0, 1.0 / rate, push)
        else:
            push()

    if not wait.subscriptions:
        reactor.call_soon(begin)
    else:
        started = time.monotonic()
        told = [False]
        many = f"{wait.subscriptions} subscription{'s' if wait.subscriptions > 1 else ''}"

        def matching(_: object = None) -> None:
            have = supplier.subscriptions(type_name)
            waited = time.monotonic() - started
            if have >= wait.subscriptions or (wait.limit and waited >= wait.limit):
                reactor.cancel_timer(waiting)
                if have < wait.subscriptions:
                    print(
                        f"miro pub: {have} of {many} to {topic} after {wait.limit:g} s "
                        "(--max-wait): publishing anyway",
                        file=sys.stderr,
                        flush=True,
                    )
                begin()
            elif not told[0] and waited >= 0.5:
                told[0] = True
                print(f"miro pub: waiting for {many} to {topic}", file=sys.stderr, flush=True)

        waiting = reactor.schedule_timer(0.0, 0.02, matching)
    server.run()
    return 0 if delivered[0] or count != 1 else 1
