"""`miro_gen.log.PeerWarnings`: what peers send is warned about once per kind and period, and
the rest counted (issue 33: 10,000 warning lines for 20,000 bad frames). A clock of the test's
own decides the periods; the summary's timer is real but short."""

from __future__ import annotations

import io
import logging
import re
import threading

from miro_gen.log import PeerWarnings


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def make(period: float = 10.0) -> tuple[PeerWarnings, io.StringIO, Clock]:
    out = io.StringIO()
    log = logging.getLogger(f"test.peer_warnings.{id(out)}")
    log.propagate = False
    handler = logging.StreamHandler(out)
    handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.DEBUG)
    clock = Clock()
    return PeerWarnings(log, period=period, clock=clock), out, clock


def lines(out: io.StringIO) -> list[str]:
    return out.getvalue().splitlines()


def test_first_logged_the_rest_counted_then_one_line_with_the_count() -> None:
    w, out, _ = make()
    for n in range(20_000):
        w.warning("dropped an event frame on %s: %s", "Events", f"frame {n}")
    assert lines(out) == ["WARNING dropped an event frame on Events: frame 0"]
    w.flush()
    assert lines(out)[1:] == [
        "WARNING 19,999 more like this in the last 10 s; the last: dropped an event frame on "
        "Events: frame 19999"
    ]
    assert w.seen == {"dropped an event frame on %s: %s": 20_000}
    w.flush()  # nothing pending: nothing more
    assert len(lines(out)) == 2


def test_kinds_are_counted_apart() -> None:
    w, out, _ = make()
    for _ in range(3):
        w.warning("dropped a request: %s", "short")
        w.warning("dropped a reply from %s: %s", "tcp://x", "short")
        w.warning("refused to bind %s", "a/b", key="refused to bind")
    assert lines(out) == [
        "WARNING dropped a request: short",
        "WARNING dropped a reply from tcp://x: short",
        "WARNING refused to bind a/b",
    ]
    w.flush()
    assert sorted(lines(out)[3:]) == [
        "WARNING 2 more like this in the last 10 s; the last: dropped a reply from tcp://x: short",
        "WARNING 2 more like this in the last 10 s; the last: dropped a request: short",
        "WARNING 2 more like this in the last 10 s; the last: refused to bind a/b",
    ]


def test_after_a_quiet_period_the_next_is_logged_again() -> None:
    w, out, clock = make()
    w.warning("dropped a request: %s", "one")
    clock.now += 11  # nothing counted meanwhile
    w.warning("dropped a request: %s", "two")
    assert lines(out) == ["WARNING dropped a request: one", "WARNING dropped a request: two"]


def test_the_count_comes_at_the_end_of_the_period_while_a_flood_goes_on() -> None:
    """One line per period, from a timer: a flood that goes on is a line every period."""
    w, out, clock = make(period=0.2)
    logged = threading.Event()
    w.log.addHandler(_OnRecord(logged))
    w.warning("dropped a request: %s", "first")
    logged.clear()
    for _ in range(500):
        w.warning("dropped a request: %s", "more")
    clock.now += 0.2
    assert logged.wait(10), lines(out)
    assert lines(out) == [
        "WARNING dropped a request: first",
        "WARNING 500 more like this in the last 0.2 s; the last: dropped a request: more",
    ]
    logged.clear()
    w.warning("dropped a request: %s", "still")  # inside the next period: counted
    assert logged.wait(10)
    assert re.fullmatch(r"WARNING 1 more like this .*: still", lines(out)[-1])


class _OnRecord(logging.Handler):
    def __init__(self, event: threading.Event) -> None:
        super().__init__()
        self.event = event

    def emit(self, record: logging.LogRecord) -> None:
        self.event.set()
