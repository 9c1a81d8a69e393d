"""NMEA sentences into Miro::GpsDataIDL readings: one reading per epoch (one fix).

A receiver reports each fix in several sentences that carry the same UTC time; `NmeaParser` puts
them together into an *epoch* and returns one reading per epoch. Fields keep their last value
until a sentence carries a new one; fields never received (or left empty by the receiver) are NaN
or 0, as the IDL says.

*When a reading goes out*: once per epoch, when the next epoch starts or at `flush()`, which the
driver calls when the receiver has been silent for a quarter of a second. Silence also ends the
epoch: a sentence after it starts the next one unless it carries the same time (a late sentence of
the fix that went out), so that a receiver acquiring satellites, which sends a GGA without time or
fix every second, gives a no-fix reading for each, and its first fix after them goes out too.
It is a fix if, at one of the moments gpsd would report the epoch, it was one, and it is the
reading as it was at the last such moment. Those moments come from the receiver's rhythm
(services/gps/nmea_cycle.py): its cycle end, learnt from the first epochs, and the sentences that
follow it; until the cycle end is known, every sentence with a position or a fix mode. An epoch
cut short before its cycle end (a receiver that skipped its last sentence, a log that stops) is
not a fix, as gpsd does not report it either.

*Valid*: at that moment, the epoch has a position, the last sentence that said anything about the
fix said there is one (services/gps/nmea.py lists what each says), no sentence said the position
is estimated, manual or simulated, and the UTC date is known. Other readings are published too,
with `valid` FALSE; `quality` says why: GGA's fix quality when the epoch had a GGA, else the first
mode indicator's (`E` GPS_FIX_ESTIMATED, `M` GPS_FIX_MANUAL, `S` GPS_FIX_SIMULATION, `N`
GPS_FIX_INVALID). A receiver in demo mode (RMC `V` with mode `S`, GGA quality 8) gives no fix.

*Dates*: from an RMC with status `A` or a ZDA. A GGA, GNS or GLL time takes the last date, moved to
the next day when the time of day jumps back by more than twelve hours (midnight). Until a date
has come, `utcTime` is the time of day and the reading is not valid; with `host_date` (the
driver's `HostDate` parameter, for receivers that send neither RMC nor ZDA) the host clock gives
the date meanwhile. A receiver without a fix that sends empty GGA or RMC (Quectel) makes the
parser forget the date and the cycle end, as gpsd does. Old receivers count GPS weeks in ten bits
and, after a week rollover (1999-08-22, 2019-04-07), report dates 1024 weeks (19.6 years) too
early; nothing in the data tells such a date from a true old one (a replayed log), so the
correction is explicit: `date_not_before` (the driver's `DateNotBefore` parameter) moves any
earlier date forward by 1024 weeks, as often as needed, and `rollovers` counts the dates so
corrected.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from datetime import UTC, date, datetime

import Miro

from .nmea import NAN, NOT_REAL, NmeaError, Q, Sentence, decode, empty_reading, time_idl
from .nmea_cycle import Cycle

DAY = 86400
ROLLOVER = 1024 * 7 * DAY  # seconds in 1024 GPS weeks


@dataclass
class Counts:
    """What the parser has seen, by outcome."""

    good: int = 0  # sentences used
    ignored: int = 0  # good sentences of types not used here
    checksum: int = 0  # bad or missing checksum
    malformed: int = 0  # good checksum, fields that do not parse


@dataclass
class Epoch:
    """The sentences of one fix so far."""

    time_of_day: float | None = None
    stamp: float = 0.0  # host time of the latest sentence
    position: bool = False  # a GGA, RMC, GNS or GLL came
    gsa: int = 0  # GSA sentences so far (one per constellation)
    fix: bool | None = None  # what the last sentence that said anything said
    quality: Miro.GpsFixQualityIDL | None = None  # GGA's, else the first mode indicator's
    not_real: bool = False  # a sentence said estimated, manual or simulated
    quality_from_gga: bool = False
    altitude_from_gga: bool = False
    fixed: Miro.GpsDataIDL | None = None  # the reading at its last report as a fix
    published: bool = False


class NmeaParser:
    """Keeps the receiver's state; `feed(sentence, stamp)` returns the readings the sentence
    completes (none, one, rarely two), `flush()` the reading of an epoch still open (see the
    module's docstring)."""

    def __init__(self, date_not_before: date | None = None, host_date: bool = False) -> None:
        self.reading = empty_reading()
        self.counts = Counts()
        self.rollovers = 0  # dates moved forward by 1024 weeks
        self.host_date = host_date
        self.not_before = (
            None
            if date_not_before is None
            else datetime.combine(date_not_before, datetime.min.time(), UTC).timestamp()
        )
        self._date: float | None = None  # midnight of the last good RMC or ZDA date
        self._date_time: float | None = None  # the time of day that date came with
        self._epoch = Epoch()
        self._cycle = Cycle()

    def feed(self, sentence: bytes, stamp: float) -> list[Miro.GpsDataIDL]:
        try:
            kind, fields, s = decode(sentence)
        except NmeaError as e:
            if e.kind == "checksum":
                self.counts.checksum += 1
            else:
                self.counts.malformed += 1
            return []
        out: list[Miro.GpsDataIDL] = []
        epoch = self._epoch
        if s is None:
            self.counts.ignored += 1
        else:
            self.counts.good += 1
            if epoch.published and (s.time_of_day is None or s.time_of_day != epoch.time_of_day):
                # The epoch went out when the receiver fell silent: what comes after the
                # silence is the next one (a timeless epoch has no time to tell them apart).
                epoch = self._epoch = Epoch()
            if s.time_of_day is not None and s.time_of_day != epoch.time_of_day:
                if epoch.time_of_day is not None:
                    out += self._close()
                epoch = self._epoch
                epoch.time_of_day = s.time_of_day
            self._apply(epoch, kind, s)
            if s.position and s.time_of_day is None and s.fix is False:
                # A receiver without a fix sending empty GGA/RMC (Quectel): gpsd forgets the
                # date and its cycle, and so do we.
                self._cycle.forget()
                self._date = None
        epoch.stamp = stamp
        data = s is not None or kind == "GSV"
        if self._cycle.report(kind, fields, data) and self._valid(epoch):
            epoch.fixed = self._reading(epoch, True)
        return out

    def flush(self) -> list[Miro.GpsDataIDL]:
        """The reading of the epoch in progress, if it has not gone out yet (the driver calls
        this when the receiver falls silent)."""
        return self._publish(self._epoch)

    def _apply(self, epoch: Epoch, kind: str, s: Sentence) -> None:
        fields = dict(s.fields)
        if kind == "GSA":
            if epoch.gsa:  # one per constellation: add them up
                fields["satellites"] = self.reading.satellites + list(fields["satellites"])  # type: ignore[call-overload]
            epoch.gsa += 1
        if kind in ("GGA", "GNS") and math.isfinite(fields.get("altitude", NAN)):  # type: ignore[arg-type]
            epoch.altitude_from_gga = True
        elif kind == "PGRMZ" and epoch.altitude_from_gga:  # GGA's altitude is the more precise
            del fields["altitude"]
        for name, value in fields.items():
            setattr(self.reading, name, value)
        if s.date is not None:
            self._date, self._date_time = self._corrected(s.date), s.time_of_day
        epoch.position |= s.position
        if s.fix is not None:
            epoch.fix = s.fix
        if s.quality is not None:
            epoch.not_real |= s.quality in NOT_REAL
            if not epoch.quality_from_gga and (kind == "GGA" or epoch.quality is None):
                epoch.quality = s.quality
                epoch.quality_from_gga = kind == "GGA"

    def _corrected(self, day: float) -> float:
        if self.not_before is not None and day < self.not_before:
            while day < self.not_before:
                day += ROLLOVER
            self.rollovers += 1
        return day

    def _valid(self, epoch: Epoch) -> bool:
        """Whether the epoch is a fix now: a position, the last word a fix, nothing estimated,
        manual or simulated, and the date known."""
        r = self.reading
        located = math.isfinite(r.latitude) and math.isfinite(r.longitude)
        if not (epoch.position and located and epoch.fix and not epoch.not_real):
            return False
        return self._utc(epoch.time_of_day, epoch.stamp)[1]

    def _close(self) -> list[Miro.GpsDataIDL]:
        """The epoch is over (another time arrived)."""
        out = self._publish(self._epoch)
        self._epoch = Epoch()
        return out

    def _publish(self, epoch: Epoch) -> list[Miro.GpsDataIDL]:
        """The epoch's reading: as it was at its last report as a fix, else as no fix."""
        if epoch.published or not epoch.position:
            return []
        epoch.published = True
        return [epoch.fixed or self._reading(epoch, False)]

    def _reading(self, epoch: Epoch, valid: bool) -> Miro.GpsDataIDL:
        r = copy.deepcopy(self.reading)
        r.utcTime = self._utc(epoch.time_of_day, epoch.stamp)[0]
        r.valid = valid
        r.quality = epoch.quality if epoch.quality is not None else Q.GPS_FIX_INVALID
        r.time = time_idl(epoch.stamp)
        return r

    def _utc(self, time_of_day: float | None, stamp: float) -> tuple[Miro.TimeIDL, bool]:
        """The fix's UTC time, and whether its date is known."""
        if time_of_day is None:
            return self.reading.utcTime, False
        if self._date is not None:
            day = self._date
            if self._date_time is not None and time_of_day < self._date_time - DAY / 2:
                day += DAY  # past midnight since the date was given
            return time_idl(day + time_of_day), True
        if self.host_date:  # the host's date, on the side of midnight nearest its clock
            day = (stamp - time_of_day + DAY / 2) // DAY * DAY
            return time_idl(day + time_of_day), True
        return time_idl(time_of_day), False


def parse_date(text: str) -> date | None:
    """`YYYY-MM-DD` (the DateNotBefore parameter), or None for an empty text."""
    if not text.strip():
        return None
    try:
        return date.fromisoformat(text.strip())
    except ValueError:
        raise ValueError(f"{text!r} is not a date (YYYY-MM-DD)") from None
