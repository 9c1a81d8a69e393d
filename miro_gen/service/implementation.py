"""`Implementation`: the manual's Implementation object, reusable (Miro's generic `...Impl`).

A sensor service's servant keeps the latest reading for polling, lets callers wait for the next
one, and publishes every reading as an event. Its producer (a device consumer, a filter, a timer)
calls `integrate_data(data)` from any thread; the IDL operations are one line each:

    class GpsImpl(Miro__POA.Gps, Implementation[Miro.GpsDataIDL]):
        def __init__(self, supplier: StructuredPushSupplier | None) -> None:
            Implementation.__init__(self, supplier, "Gps", initial=Miro.GpsDataIDL(), timeout=2)

        def getData(self) -> Miro.GpsDataIDL:
            return self.latest()

        def getWaitData(self) -> Miro.GpsDataIDL:
            return self.wait_next(Miro.ETimeOut)

Waiting happens on the server's worker pool, never on the reactor thread.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Generic, TypeVar

from miro_gen import clock

if TYPE_CHECKING:
    from miro_gen.transport.events import StructuredPushSupplier

T = TypeVar("T")


class Implementation(Generic[T]):
    """Latest value, waiters woken on each new one, and an event per value.

    `supplier` (or None, for a service that only answers polls) publishes events of
    `type_name`; `initial` is what `latest()` returns before the first value; `timeout` is how
    long `wait_next()` waits by default, in seconds."""

    def __init__(
        self,
        supplier: StructuredPushSupplier | None,
        type_name: str,
        *,
        initial: T | None = None,
        timeout: float = 1.0,
    ) -> None:
        self.supplier = supplier
        self.type_name = type_name
        self.timeout = timeout
        self._changed = threading.Condition()
        self._latest: T | None = initial
        self._stamp = 0.0
        self._count = 0  # values integrated so far
        self.published = 0  # values pushed to a subscriber
        self.waiting = 0  # callers in wait_next() now

    def integrate_data(self, data: T, stamp: float | None = None) -> None:
        """Keep `data` as the latest value, wake the callers waiting for it, and push it as an
        event (encoded only when someone subscribes). `stamp`: when it was measured (now)."""
        stamp = clock.now() if stamp is None else stamp
        with self._changed:
            self._latest = data
            self._stamp = stamp
            self._count += 1
            self._changed.notify_all()
        if self.supplier is not None and self.supplier.push(self.type_name, data, stamp):
            self.published += 1

    @property
    def count(self) -> int:
        """How many values have been integrated."""
        return self._count

    @property
    def stamp(self) -> float:
        """When the latest value was measured (seconds since the epoch; 0 before the first)."""
        return self._stamp

    def latest(self) -> T:
        """The latest value (`initial` before the first one; LookupError without it)."""
        with self._changed:
            if self._latest is not None:
                return self._latest
        raise LookupError(f"no {self.type_name} value yet")

    def wait_next(
        self, timed_out: type[Exception] | None = None, timeout: float | None = None
    ) -> T:
        """The next value integrated after this call, waiting at most `timeout` seconds (the
        default set at construction). On timeout raise `timed_out(what=...)` when given (an IDL
        exception such as Miro.ETimeOut), else TimeoutError."""
        limit = self.timeout if timeout is None else timeout
        with self._changed:
            seen = self._count
            self.waiting += 1
            try:
                if self._changed.wait_for(lambda: self._count != seen, limit):
                    return self._latest  # type: ignore[return-value]
            finally:
                self.waiting -= 1
        what = f"no new {self.type_name} value within {limit:g} s"
        if timed_out is None:
            raise TimeoutError(what)
        try:
            make: Callable[..., Exception] = timed_out
            error = make(what=what)
        except TypeError:  # an exception without a `what` member
            error = timed_out()
        raise error
