"""Rate statistics of a stream of events, for `miro hz` (like rostopic hz)."""

from __future__ import annotations

import math
from collections import deque


class RateWindow:
    """The periods between the last `window` + 1 arrivals: their rate, min, max and spread;
    their bandwidth; and the lag of the last `window` arrivals (how long after its push each
    one arrived)."""

    def __init__(self, window: int = 100) -> None:
        self.periods: deque[float] = deque(maxlen=window)
        self.sizes: deque[int] = deque(maxlen=window)  # bytes of the arrivals ending a period
        self.lags: deque[float] = deque(maxlen=window)
        self.last: float | None = None
        self.count = 0

    def add(self, t: float, size: int = 0, lag: float | None = None) -> None:
        """An arrival at `t` seconds, of `size` bytes, `lag` seconds after it was pushed."""
        if self.last is not None:
            self.periods.append(t - self.last)
            self.sizes.append(size)
        self.last = t
        self.count += 1
        if lag is not None:
            self.lags.append(lag)

    def lag(self) -> tuple[float, float] | None:
        """(mean, max) lag in seconds, or None before the first arrival with one."""
        if not self.lags:
            return None
        return sum(self.lags) / len(self.lags), max(self.lags)

    def bandwidth(self) -> float | None:
        """Bytes a second over the window, or None before two arrivals."""
        if not self.periods:
            return None
        span = sum(self.periods)
        return sum(self.sizes) / span if span > 0 else math.inf

    def stats(self) -> tuple[float, float, float, float] | None:
        """(rate Hz, min s, max s, standard deviation s), or None before two arrivals."""
        n = len(self.periods)
        if n == 0:
            return None
        mean = sum(self.periods) / n
        std = math.sqrt(sum((p - mean) ** 2 for p in self.periods) / n)
        rate = 1 / mean if mean > 0 else math.inf
        return rate, min(self.periods), max(self.periods), std


def data_rate(bytes_per_second: float) -> str:
    """`12.3 MB/s`, in decimal units as network rates are."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if bytes_per_second >= scale:
            return f"{bytes_per_second / scale:.3g} {unit}/s"
    return f"{bytes_per_second:.3g} B/s"
