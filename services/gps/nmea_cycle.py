"""When a receiver has said all it says about a fix: the end-of-cycle detection of gpsd.

gpsd, the reference decoder the driver is checked against, reports a fix at moments it learns
from the receiver's own rhythm, and what it reports are the fixes users compare with. `Cycle`
follows the same rules (read from gpsd's behaviour on its regression logs and its documented
design, not its code):

- sentences with a time: GGA, GLL, GNS and ZDA with their time, RMC with status A, time and date,
  and GBS and Sirf's PSRFEPE (read for their time only);
- when a sentence's time differs from the previous timed sentence's (by more than 10 ms), a new
  cycle starts, and the previous timed sentence's type becomes a *cycle ender* (enders are
  never forgotten, except that GLL, which some receivers send after the others with no new
  time, takes over its predecessor's role: it "continues" the cycle);
- a report is due at a timed (or continuing) sentence of an ender's type, and at a sentence with
  data right after an ender; a GSV in the middle of its series is neither;
- until an ender is known, or after a receiver without a fix sends a GGA or RMC without a time
  (some Quectel modules), the cycle end is not reliable: a report is due at every sentence that
  carries a position or a fix mode.
"""

from __future__ import annotations

import math

TIMED = {"GGA": 0, "GLL": 4, "GNS": 0, "ZDA": 0, "RMC": 0, "GBS": 0, "PSRFEPE": 0}
CONTINUES = {"GLL"}  # sentences that extend the cycle
POSITION_OR_MODE = {"GGA", "RMC", "GLL", "GNS", "GSA", "PGRMZ"}


def timed(kind: str, fields: list[str]) -> float | None:
    """The time of day gpsd would take the sentence as marking (None: it marks none)."""
    at = TIMED.get(kind)
    if at is None or len(fields) <= at:
        return None
    if kind == "RMC" and not (len(fields) > 8 and fields[1] == "A" and fields[8]):
        return None
    if kind == "ZDA" and not (len(fields) > 3 and all(fields[:4])):
        return None
    text = fields[at]
    if len(text) < 6 or not text[:6].isdigit():
        return None
    try:
        return int(text[:2]) * 3600 + int(text[2:4]) * 60 + float(text[4:])
    except ValueError:
        return None


class Cycle:
    """gpsd's end-of-cycle detector: `report(kind, fields, data)` says whether this sentence
    (`data`: it carried something gpsd uses) is a moment gpsd would report at."""

    def __init__(self) -> None:
        self.enders: set[str] = set()
        self.reliable = False
        self._last_timed: str | None = None  # the type of the last timed sentence
        self._last_time: float | None = None

    def forget(self) -> None:
        """A receiver without a fix sent a position sentence without a time."""
        self.reliable = False

    def report(self, kind: str, fields: list[str], data: bool) -> bool:
        if kind == "GSV" and len(fields) > 1 and fields[0] != fields[1]:
            return False  # more of the series to come
        time = timed(kind, fields)
        continues = kind in CONTINUES
        due = False
        if time is not None:
            changed = self._last_time is None or math.fabs(time - self._last_time) > 0.01
            last = self._last_timed
            if changed and last is not None and not continues and last not in self.enders:
                self.enders.add(last)
                self.reliable = True
            self._last_time = time
        else:
            if self._last_timed in self.enders and data:
                due = True
            if continues and self._last_timed is not None:
                self.enders.discard(self._last_timed)
                self.enders.add(kind)
                self.reliable = True
        if (time is not None or continues) and kind in self.enders:
            due = True
        if time is not None:
            self._last_timed = kind
        if not self.reliable and data and kind in POSITION_OR_MODE:
            due = True
        return due
