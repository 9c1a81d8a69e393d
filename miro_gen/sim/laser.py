"""A laser scanner on an event channel, for `miro sim laser`: scans of a room with a pillar going
to and fro (`miro_gen.sim.scip.RoomScene`), published as Miro::RangeScanEventIDL events at the
scanner's rate, with no device and no driver in between. By default a UTM-30LX: 1,081 beams
over 270 degrees, 40 scans a second.

Ranges are millimetres, `RangeSensor::HORIZON_RANGE` where nothing reflects within range. The
pillar's motion repeats, so do the scans: each is computed once and kept (a few MB at most).
"""

from __future__ import annotations

from array import array
from typing import Any

import Miro

from miro_gen import clock
from miro_gen.devices.scip import Geometry
from miro_gen.sim.scip import NO_ECHO, RoomScene
from miro_gen.transport.events import StructuredPushSupplier

FIELD_OF_VIEW = 270.0  # degrees, from the first beam to the last
_HORIZON = Miro.RangeSensor.HORIZON_RANGE


class LaserScans:
    """The scans of a scanner with `beams` beams turning `rate` times a second in a room."""

    def __init__(self, beams: int = 1081, rate: float = 40.0, scene: RoomScene | None = None):
        if beams < 2 or rate <= 0:
            raise ValueError("a laser scanner has at least 2 beams and a rate above 0")
        self.beams = beams
        self.rate = rate
        self.scene = scene if scene is not None else RoomScene()
        steps_per_turn = round((beams - 1) * 360 / FIELD_OF_VIEW)
        self.geometry = Geometry(
            "simulated", 23, 60000, steps_per_turn, 0, beams - 1, (beams - 1) // 2, 2400
        )
        self.cycle = max(1, round(self.scene.period * rate))  # scans before they repeat
        self._scans: dict[int, array[int]] = {}

    def scan(self, n: int) -> array[int]:
        """Scan number `n` (counted from 0 at the pillar's start)."""
        key = n % self.cycle
        ranges = self._scans.get(key)
        if ranges is None:
            measured = self.scene.ranges(key / self.rate, self.geometry)
            ranges = array("i", [_HORIZON if r == NO_ECHO else r for r in measured])
            self._scans[key] = ranges
        return ranges


def time_idl(seconds: float) -> Miro.TimeIDL:
    sec = int(seconds // 1)
    return Miro.TimeIDL(sec, min(999_999, round((seconds - sec) * 1e6)))


class LaserPublisher:
    """Takes one scan per run of a reactor timer (`handle_timeout`) and pushes it, stamped with
    the time it is taken, as event type `type_name`. `taken` counts the scans, `published`
    those pushed while someone subscribed."""

    def __init__(self, supplier: StructuredPushSupplier, scans: LaserScans, type_name: str):
        self.supplier = supplier
        self.scans = scans
        self.type_name = type_name
        self.taken = 0
        self.published = 0

    def handle_timeout(self, _arg: Any = None) -> None:
        now = clock.current().now()
        event = Miro.RangeScanEventIDL(time_idl(now), [self.scans.scan(self.taken)])
        self.taken += 1
        if self.supplier.push(self.type_name, event, stamp=now):
            self.published += 1
