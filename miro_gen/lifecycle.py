"""A service's life, from the first line of its start to the end of its clean-up: what SIGINT
(Ctrl-C) and SIGTERM do at each moment, and one-line errors instead of tracebacks.

    from miro_gen.lifecycle import defer_signals, run_main

    if __name__ == "__main__":
        defer_signals()  # first: a signal during the imports is kept, not raised
    ...imports...

    def main() -> int: ...

    if __name__ == "__main__":
        run_main(main, "exampleA")

* While a service imports and starts (`defer_signals`), a signal is remembered, even one the
  shell would have ignored (a background job of a script ignores SIGINT): it takes effect at
  `run_main`, which then ends the process at once with status 128 + the signal (130 for
  Ctrl-C), without a traceback.
* Inside `main`, a signal raises KeyboardInterrupt, as Python does by default, so that a client
  waiting for a reply or sleeping between polls stops; `run_main` turns it into the same quiet
  exit.
* While `Server.run()` serves, a signal stops it (`signals_stop`): it returns, its names are
  unbound, and `main` goes on; during that clean-up further signals are ignored.
* `run_main` prints the failures a user can act on as one line, `prog: what failed ...`, and
  exits 1 (2 for a bad command line): the naming service or a server that cannot be reached, a
  name not bound, a run-time parameter document that does not fit. Which failures those are is
  for their own floors to say (`miro_gen.exceptions.ActionableError` and `actionable`): this
  module looks at no other.

Signal handlers can only be set on the main thread; elsewhere these are no-ops. The module
imports nothing heavy: a service imports it before anything else.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import NoReturn

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _State:
    installed = False  # our handler is in place
    mode = "raise"  # "defer": remember the signal; "raise": KeyboardInterrupt; "stop": call stop
    pending: int | None = None  # a signal remembered in "defer" mode
    last: int = signal.SIGINT  # the last signal received, for the exit status
    stop: Callable[[], object] | None = None


def _handler(signum: int, frame: FrameType | None) -> None:
    _State.last = signum
    if _State.mode == "stop" and _State.stop is not None:
        _State.stop()
    elif _State.mode == "raise":
        _State.pending = None
        raise KeyboardInterrupt
    else:  # "defer", or "stop" during a clean-up
        _State.pending = signum


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _install() -> bool:
    """Put our handler in place (main thread only); whether it is."""
    if not _State.installed and _main_thread():
        for sig in SIGNALS:
            signal.signal(sig, _handler)
        _State.installed = True
    return _State.installed


def defer_signals() -> None:
    """From now until `run_main` (or `Server.run`), remember SIGINT and SIGTERM instead of
    raising: call it first thing in a service, before its imports."""
    if _install():
        _State.mode = "defer"


def interrupted() -> bool:
    """Whether a signal has been remembered and not acted on yet."""
    return _State.pending is not None


def exit_status() -> int:
    """The exit status of a process ended by the last signal: 128 + its number."""
    return 128 + int(_State.last)


_cleanups: list[Callable[[], object]] = []  # what a signal before Server.run() must undo


def at_interrupt(fn: Callable[[], object]) -> None:
    """Have `run_main` call `fn()` when a signal ends `main` (a server that bound its names and
    was interrupted before it ran unbinds them); `forget(fn)` takes it back."""
    _cleanups.append(fn)


def forget(fn: Callable[[], object]) -> None:
    if fn in _cleanups:
        _cleanups.remove(fn)


class Stopping:
    """What `signals_stop` yields: whether a signal came before, and the switch to clean-up."""

    def __init__(self, active: bool) -> None:
        self.active = active

    @property
    def pending(self) -> bool:
        return _State.pending is not None

    def cleaning_up(self) -> None:
        """From now on, signals are ignored (remembered only): the clean-up must finish."""
        if self.active:
            _State.mode = "defer"


@contextmanager
def signals_stop(stop: Callable[[], object]) -> Iterator[Stopping]:
    """While inside, SIGINT and SIGTERM call `stop()` instead of raising; afterwards, what was
    there before is back (a signal that came during the clean-up is forgotten)."""
    if not _main_thread():
        yield Stopping(False)
        return
    was_installed = _State.installed
    old = {sig: signal.getsignal(sig) for sig in SIGNALS} if not was_installed else {}
    _install()
    saved = _State.mode, _State.stop
    _State.mode, _State.stop = "stop", stop
    try:
        yield Stopping(True)
    finally:
        _State.mode, _State.stop = saved
        _State.pending = None
        if not was_installed:
            for sig, handler in old.items():
                signal.signal(sig, handler)
            _State.installed = False
            _State.mode = "raise"


def run_main(main: Callable[[], int | None], prog: str) -> NoReturn:
    """Run a service's `main()` and exit with its status: 128 + the signal after SIGINT or
    SIGTERM (130 for Ctrl-C), also one that came during the imports; one line and status 1
    (2 for a bad command line) for the failures `describe` knows; a traceback for the rest,
    which are defects."""
    try:  # (a signal right after the switch to "raise" is caught here too)
        if _install():
            _State.mode = "raise"
        if _State.pending is not None:
            _State.pending = None
            raise KeyboardInterrupt
        code = main()
    except KeyboardInterrupt:
        code = exit_status()
        _clean_up()
    except SystemExit:
        raise
    except Exception as exc:
        known = describe(exc)
        if known is None:
            raise
        message, code = known
        print(f"{prog}: {message}", file=sys.stderr)
        if os.environ.get("MIRO_DEBUG"):
            import traceback

            traceback.print_exc()
    sys.stdout.flush()
    sys.exit(code or 0)


def _clean_up() -> None:
    """Run what `at_interrupt` registered, newest first, with signals ignored meanwhile."""
    if _install():
        _State.mode = "defer"
    while _cleanups:
        fn = _cleanups.pop()
        try:
            fn()
        except Exception as exc:  # the process is ending: say so, go on with the others
            print(f"clean-up failed: {exc}", file=sys.stderr)


def describe(exc: BaseException) -> tuple[str, int] | None:
    """A one-line message and exit status for a failure a user can act on (an ActionableError,
    or a class its floor made actionable: miro_gen.exceptions); None for others."""
    from miro_gen.exceptions import user_message

    return user_message(exc)
