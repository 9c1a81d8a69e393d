"""What this process's suppliers publish and its consumers subscribe to, as its service object
describes them (`miro list`, `miro pub`). A supplier offers an event type with its first push
of it; a consumer's subscriptions are recorded when set and forgotten when it closes."""

from __future__ import annotations

import threading
from typing import Any, NamedTuple


class Offer(NamedTuple):
    channel: str
    domain: str
    type_name: str
    payload: str  # the payload's IDL type (Miro::ExampleEventIDL)
    type_hash: str


_lock = threading.Lock()
_offers: dict[tuple[str, str, str], Offer] = {}
_subscriptions: dict[int, tuple[str, list[tuple[str, str]]]] = {}


def offered(channel: str, domain: str, type_name: str, payload: Any) -> None:
    """A supplier pushed its first `payload` of `type_name` (or one of another type)."""
    offer = Offer(
        channel,
        domain,
        type_name,
        str(getattr(payload, "_type_name", type(payload).__name__)),
        str(getattr(payload, "_type_hash", "")),
    )
    with _lock:
        _offers[(channel, domain, type_name)] = offer


def subscribed(consumer: object, channel: str, subscriptions: list[tuple[str, str]]) -> None:
    with _lock:
        _subscriptions[id(consumer)] = (channel, list(subscriptions))


def unsubscribed(consumer: object) -> None:
    with _lock:
        _subscriptions.pop(id(consumer), None)


def offers() -> list[Offer]:
    with _lock:
        return sorted(_offers.values())


def subscriptions() -> list[tuple[str, str, str]]:
    """(channel, domain, type name) of every consumer of this process, once each."""
    with _lock:
        found = {(c, d, t) for c, subs in _subscriptions.values() for d, t in subs}
    return sorted(found)
