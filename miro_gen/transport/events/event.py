"""One event as a consumer receives it: what its handler (`push_structured_event`) is given,
and what waits for that handler in the consumer's queue (transport.events.queue), its payload
still encoded until it is delivered."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(slots=True)
class StructuredEvent:
    """One event as a consumer receives it."""

    domain_name: str
    type_name: str
    payload: Any  # the decoded generated type
    seq: int
    stamp: float  # source time, seconds since the epoch
    publish_time: float  # when the supplier sent it, seconds since the epoch
    supplier: int = 0  # the supplier's random id
    type_hash: str = ""
