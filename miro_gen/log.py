"""Miro's logging on Python's `logging`: ten levels, categories, and `-MLL` / `-MLF`.

Miro prints a message when its level is at most the log level (`-MLL`, default 4, warning) and
its category is selected (`-MLF`, default all). Levels, most to least urgent: 0 emergency,
1 alert, 2 critical, 3 error, 4 warning, 5 notice, 6 ctor/dtor, 7 debug, 8 trace, 9 prattle.
Each category is the Python logger `miro.<CATEGORY>`; the levels are Python levels, named, so
ordinary handlers and formatters work. The manual's

    MIRO_DBG_OSTR(MIRO, LL_DEBUG, "Map Size:" << size)

is

    log = miro_gen.log.logger("MIRO")
    log.log(LL_DEBUG, "Map Size: %s", size)      # or log.debug(...), log.trace(...), ...
"""

from __future__ import annotations

import atexit
import logging
import sys
import threading
import time
import weakref
from collections.abc import Callable, Iterable
from typing import Any, TextIO

LL_EMERGENCY = 0
LL_ALERT = 1
LL_CRITICAL = 2
LL_ERROR = 3
LL_WARNING = 4
LL_NOTICE = 5
LL_CTOR_DTOR = 6
LL_DEBUG = 7
LL_TRACE = 8
LL_PRATTLE = 9

# Miro level -> (Python level, name). Warning, error, critical and debug are Python's own.
_LEVELS: dict[int, tuple[int, str]] = {
    LL_EMERGENCY: (58, "EMERGENCY"),
    LL_ALERT: (55, "ALERT"),
    LL_CRITICAL: (logging.CRITICAL, "CRITICAL"),
    LL_ERROR: (logging.ERROR, "ERROR"),
    LL_WARNING: (logging.WARNING, "WARNING"),
    LL_NOTICE: (25, "NOTICE"),
    LL_CTOR_DTOR: (15, "CTOR_DTOR"),
    LL_DEBUG: (logging.DEBUG, "DEBUG"),
    LL_TRACE: (5, "TRACE"),
    LL_PRATTLE: (1, "PRATTLE"),
}
for _python, _name in _LEVELS.values():
    logging.addLevelName(_python, _name)

ROOT = "miro"  # the parent of every category's logger
CATEGORIES = ("MIRO",)  # the middleware's own; services add theirs just by using them


def python_level(miro_level: int) -> int:
    """The Python logging level of a Miro level (0..9)."""
    try:
        return _LEVELS[miro_level][0]
    except KeyError:
        raise ValueError(f"Miro log levels go from 0 to 9, not {miro_level}") from None


class MiroLogger(logging.LoggerAdapter[logging.Logger]):
    """A category's logger, with a method for each Miro level Python lacks. `log()` also takes
    Miro levels (0..9): `log.log(LL_DEBUG, ...)`."""

    def log(self, level: int, msg: object, *args: Any, **kwargs: Any) -> None:
        super().log(python_level(level) if 0 <= level <= 9 else level, msg, *args, **kwargs)

    def emergency(self, msg: object, *args: Any, **kwargs: Any) -> None:
        self.logger.log(_LEVELS[LL_EMERGENCY][0], msg, *args, **kwargs)

    def alert(self, msg: object, *args: Any, **kwargs: Any) -> None:
        self.logger.log(_LEVELS[LL_ALERT][0], msg, *args, **kwargs)

    def notice(self, msg: object, *args: Any, **kwargs: Any) -> None:
        self.logger.log(_LEVELS[LL_NOTICE][0], msg, *args, **kwargs)

    def ctor_dtor(self, msg: object, *args: Any, **kwargs: Any) -> None:
        self.logger.log(_LEVELS[LL_CTOR_DTOR][0], msg, *args, **kwargs)

    def trace(self, msg: object, *args: Any, **kwargs: Any) -> None:
        self.logger.log(_LEVELS[LL_TRACE][0], msg, *args, **kwargs)

    def prattle(self, msg: object, *args: Any, **kwargs: Any) -> None:
        self.logger.log(_LEVELS[LL_PRATTLE][0], msg, *args, **kwargs)


def logger(category: str = "MIRO") -> MiroLogger:
    """The logger of a category (`"MIRO"`, `"SICK"`, ...): Python's `miro.<CATEGORY>`."""
    return MiroLogger(logging.getLogger(f"{ROOT}.{category}"), {})


class _CategoryFilter(logging.Filter):
    """Lets through the records of the selected categories (all when none is selected)."""

    def __init__(self, categories: Iterable[str]) -> None:
        super().__init__()
        self.categories = frozenset(categories)

    def filter(self, record: logging.LogRecord) -> bool:
        if not self.categories:
            return True
        category = record.name[len(ROOT) + 1 :].split(".", 1)[0]
        return category in self.categories


_HANDLER_MARK = "_miro_gen_handler"


def configure(
    level: int = LL_WARNING, categories: Iterable[str] = (), stream: TextIO | None = None
) -> None:
    """Apply `-MLL level` and `-MLF categories`: what the `miro.*` loggers print, on `stream`
    (default stderr) as `[LEVEL CATEGORY] message`. Calling it again replaces the setting."""
    root = logging.getLogger(ROOT)
    root.setLevel(python_level(level))
    root.propagate = False
    for h in list(root.handlers):
        if getattr(h, _HANDLER_MARK, False):
            root.removeHandler(h)
    handler = logging.StreamHandler(stream if stream is not None else sys.stderr)
    setattr(handler, _HANDLER_MARK, True)
    handler.setFormatter(_MiroFormatter())
    handler.addFilter(_CategoryFilter(categories))
    root.addHandler(handler)


class _MiroFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        category = record.name[len(ROOT) + 1 :] or ROOT
        text = f"[{record.levelname} {category}] {record.getMessage()}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return text


# -- warnings about peers, rate-limited -------------------------------------------------------

PEER_WARNING_PERIOD = 10.0  # seconds: at most one line per kind of warning and period
_MAX_KINDS = 256


class _Kind:
    """One kind of peer warning: when its period ends, what was counted since its last line."""

    __slots__ = ("count", "ends", "last")

    def __init__(self, ends: float) -> None:
        self.ends = ends
        self.count = 0
        self.last: tuple[str, tuple[object, ...]] = ("", ())


class PeerWarnings:
    """Warnings about what peers send (malformed frames, unknown types, refused requests): the
    one owner of their rate limit. A peer decides how often these happen, so each is not a line:
    the first of a kind is logged as it is; the others within `period` seconds are counted,
    and at the end of the period one line says how many and shows the last ("1,234 more like
    this in the last 10 s; the last: dropped an event frame on X: ..."). 20,000 bad frames in a
    few seconds make two lines. A kind is the message's format string, or `key`. Counts still
    pending are logged by `flush()` and when the process exits. Thread-safe; the summary is
    logged from a timer thread."""

    def __init__(
        self,
        log: logging.Logger | logging.LoggerAdapter[logging.Logger],
        period: float = PEER_WARNING_PERIOD,
        level: int = logging.WARNING,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.log = log
        self.period = period
        self.level = level
        self._clock = clock
        self._lock = threading.Lock()
        self._kinds: dict[str, _Kind] = {}
        self.seen: dict[str, int] = {}  # kind -> warnings in all, logged or counted
        _all_peer_warnings.add(self)

    def warning(self, msg: str, *args: object, key: str | None = None) -> None:
        kind = key if key is not None else msg
        now = self._clock()
        with self._lock:
            if kind not in self._kinds and len(self._kinds) >= _MAX_KINDS:
                kind = "(other kinds)"
            self.seen[kind] = self.seen.get(kind, 0) + 1
            state = self._kinds.get(kind)
            if state is not None and (now < state.ends or state.count):
                state.count += 1
                state.last = (msg, args)
                if state.count == 1:  # the first counted in this period: a line at its end
                    timer = threading.Timer(max(0.0, state.ends - now), self._summarise, (kind,))
                    timer.daemon = True
                    timer.start()
                return
            self._kinds[kind] = _Kind(now + self.period)
        self.log.log(self.level, msg, *args)

    def _summarise(self, kind: str) -> None:
        with self._lock:
            state = self._kinds.get(kind)
            if state is None or not state.count:
                return
            count, (msg, args) = state.count, state.last
            state.ends, state.count = self._clock() + self.period, 0
        self._summary(count, msg, args)

    def _summary(self, count: int, msg: str, args: tuple[object, ...]) -> None:
        try:
            last = msg % args if args else msg
        except (TypeError, ValueError):
            last = msg
        self.log.log(
            self.level,
            "%s more like this in the last %g s; the last: %s",
            f"{count:,}",
            self.period,
            last,
        )

    def flush(self) -> None:
        """Log the counts still pending now (at the end of a flood, a test, the process)."""
        with self._lock:
            pending = [(s.count, s.last) for s in self._kinds.values() if s.count]
            for s in self._kinds.values():
                s.count = 0
        for count, (msg, args) in pending:
            self._summary(count, msg, args)


_all_peer_warnings: weakref.WeakSet[PeerWarnings] = weakref.WeakSet()


@atexit.register
def _flush_peer_warnings() -> None:
    # Only where logging was set up (a service's -MLL handler): a stream may be closed at exit
    # already (a test runner's capture), and then nothing is said rather than a logging error.
    raising, logging.raiseExceptions = logging.raiseExceptions, False
    try:
        for w in list(_all_peer_warnings):
            if w.log.hasHandlers():
                w.flush()
    finally:
        logging.raiseExceptions = raising
