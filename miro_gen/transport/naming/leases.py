"""The names a server keeps in the naming service, from its first bind to its last unbind.

* A name is bound taking it over from an earlier run of the same service (the same principal,
  which the naming service checks, and the same service name: a restart by `miro launch` or by
  hand), at once and without a warning: the run it replaces may have been killed a moment ago,
  its lease still running.
* A name that another owner holds is not given up on, and the server does not stop: it says
  so loudly (a warning at once, and again every minute), serves its other names, and binds
  the name when it is free (tried every half second).
* A naming service that does not answer yet is waited for, said once with its address and
  what to start (as ROS 1 nodes wait for their master); `--wait-naming SECONDS` bounds the
  wait, and Ctrl-C ends it.
* Every third of a lease one `renew_as` extends the leases of all the names held; those it
  says are lost (a lease ran out while the server was cut off, or the naming service lost
  them) are bound again, without taking over: a newer run of the service keeps what it took,
  and this one says so.
* At the end every name is unbound.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import MiroNaming

from miro_gen import lifecycle
from miro_gen.exceptions import TRANSIENT, SystemException
from miro_gen.log import logger
from miro_gen.runtime.rpc import Invoker
from miro_gen.transport.naming.client import NamingClient, naming_errors
from miro_gen.transport.rpc.invoker import REFUSED_MINOR

_log = logger("MIRO")

BIND_TIMEOUT = 5.0  # seconds a bind may take
RENEW_TIMEOUT = 2.0  # seconds a lease renewal may take
RETRY_HELD = 0.5  # seconds between attempts to bind a name that another owner holds
REMIND_EVERY = 60.0  # seconds between two warnings that a name is still held by another
WAIT_STEP = 0.5  # at most this many seconds between two tries of an unreachable naming service


@dataclass
class _Wanted:
    """A name to bind once its holder lets it go."""

    entry: MiroNaming.Entry
    holder: str
    since: float
    told: float


class Leases:
    """The names of one server: `owner` (its service and this run), leases of `lease`
    seconds, naming calls through `invoker`; `wait_naming` bounds the wait for an unreachable
    naming service (None: no bound); `unreachable` turns that failure into the message to
    raise. (A `NameKeeper`, service.backbone.)"""

    leased = True  # a name outlives its server until its lease ends

    def __init__(
        self,
        naming: NamingClient,
        invoker: Invoker,
        owner: MiroNaming.Owner,
        lease: float,
        wait_naming: float | None = None,
        unreachable: Callable[[TRANSIENT], TRANSIENT] = lambda e: e,
    ) -> None:
        self.naming = naming
        self.owner = owner
        self.lease = lease
        self.wait_naming = wait_naming
        self.unreachable = unreachable
        self._registry = naming.registry_stub(invoker, BIND_TIMEOUT, owner=True)
        self._invoker = invoker
        self._held: dict[str, MiroNaming.Entry] = {}
        self._wanted: dict[str, _Wanted] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._answered = False  # the naming service has answered once
        # Called (from the renewing thread) when that thread changed the names held: one bound
        # once its holder let it go, one another run took. What keeps something beside each
        # name held (a liveliness token over Zenoh, transport.zenoh.names) follows from here.
        self.on_held_changed: Callable[[], object] | None = None

    @property
    def lease_ms(self) -> int:
        return int(self.lease * 1000)

    # ---- the server's thread ------------------------------------------------------------------

    def bind(self, entry: MiroNaming.Entry) -> bool:
        """Bind `entry` (taking it over from an earlier run of this service) and keep it;
        False when another owner holds it: it is bound when free, and said so meanwhile. Waits
        for a naming service that has not answered yet (`wait_for_naming`)."""
        self.wait_for_naming()
        try:
            with naming_errors(self.naming.endpoint, f"bind {entry.name}"):
                self._registry.bind_as(entry, self.owner, self.lease_ms, True)
        except TRANSIENT as e:
            raise self.unreachable(e) from None
        except MiroNaming.AlreadyBound as e:
            self._want(entry, e.holder, "is held by")
            return False
        self.keep(entry)
        return True

    def wait_for_naming(self) -> None:
        """Until the naming service first answers (through the socket this server binds
        through), try it at growing intervals, having said once where it is expected and what
        to start; TRANSIENT after `wait_naming` seconds, or at once when it refuses the
        connection (no key). Returns at once after it has answered."""
        if self._answered:
            return
        start = time.monotonic()
        said = False
        step = 0.05
        while True:
            try:
                with naming_errors(self.naming.endpoint, "bind names"):
                    self._registry.renew_as(self.owner, [], self.lease_ms)
                break
            except TRANSIENT as e:
                if self._over_tcp_instead():
                    continue
                waited = time.monotonic() - start
                if e.minor == REFUSED_MINOR or (
                    self.wait_naming is not None and waited >= self.wait_naming
                ):
                    raise self.unreachable(e) from None
                if not said:
                    said = True
                    explained = self.unreachable(e)
                    if explained is not e:  # not a miro naming service at all: say so
                        raise explained from None
                    self._say_waiting(e)
                self._sleep(step, start)
                step = min(step * 2, WAIT_STEP)
        self._answered = True
        if said:
            _log.notice("the naming service at %s answers", self.naming.endpoint)

    def _over_tcp_instead(self) -> bool:
        """The naming service's local socket did not answer: whether its TCP endpoint does
        (its machine's, seen from another network namespace, such as a container's), so that
        this server binds over TCP from now on. BAD_OPERATION: it speaks another version."""
        if self.naming.owner_fixed or self.naming.owner_endpoint == self.naming.endpoint:
            return False
        try:
            with naming_errors(self.naming.endpoint, "bind names"):
                self.naming.registry.list_page("", "", 1)
        except TRANSIENT:
            return False
        _log.notice(
            "the naming service at %s answers over TCP, not at %s: binding over TCP",
            self.naming.endpoint,
            self.naming.owner_endpoint,
        )
        self.naming.owner_endpoint = self.naming.endpoint
        self._registry = self.naming.registry_stub(self._invoker, BIND_TIMEOUT, owner=True)
        return True

    def _say_waiting(self, error: TRANSIENT) -> None:
        bound = (
            f"; giving up after {self.wait_naming:g} s (--wait-naming)"
            if self.wait_naming is not None
            else " (Ctrl-C to stop; --wait-naming SECONDS bounds the wait)"
        )
        reason = error.message.rsplit("(", 1)[-1].split(")")[0] if "(" in error.message else ""
        _log.warning(
            "the naming service at %s does not answer%s: start it with `miro naming` "
            "(or `miro launch`), or give --naming; waiting for it%s",
            self.naming.endpoint,
            f" ({reason})" if reason else "",
            bound,
        )

    def _sleep(self, step: float, start: float) -> None:
        """Sleep `step` seconds (cut at the wait's bound); a signal remembered meanwhile
        (`lifecycle.defer_signals`) ends the wait as Ctrl-C would."""
        if self.wait_naming is not None:
            step = max(0.0, min(step, start + self.wait_naming - time.monotonic()))
        end = time.monotonic() + step
        while True:
            if lifecycle.interrupted():
                raise KeyboardInterrupt
            left = end - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, 0.05))

    def claim(self, entry: MiroNaming.Entry, *, take_over: bool, timeout: float) -> bool:
        """Bind `entry` once and keep it, from any thread (through that thread's own sockets),
        with calls of `timeout` seconds and without waiting for the naming service; False when
        the server stopped meanwhile (then it is unbound again). MiroNaming.AlreadyBound when
        another owner holds it: not retried."""
        registry = self.naming.registry_stub(self._invoker, timeout, owner=True)
        registry.bind_as(entry, self.owner, self.lease_ms, take_over)
        if not self.keep(entry):  # the server stopped meanwhile: leave nothing behind
            registry.unbind_as(entry.name, self.owner)
            return False
        return True

    def keep(self, entry: MiroNaming.Entry) -> bool:
        """Keep `entry`, bound already, under this server's lease (renewed, bound again when
        lost, unbound at the end); False when the server is stopping."""
        with self._lock:
            if self._stop.is_set():
                return False
            self._held[entry.name] = entry
            self._wanted.pop(entry.name, None)
        self._start()
        return True

    def want(self, entry: MiroNaming.Entry, holder: str) -> None:
        """Bind `entry` as soon as its holder (as the naming service described it) lets it go."""
        self._want(entry, holder, "is held by")

    def held(self) -> list[MiroNaming.Entry]:
        with self._lock:
            return list(self._held.values())

    def remove(self, name: str) -> None:
        """Stop keeping `name` and unbind it."""
        with self._lock:
            self._held.pop(name, None)
            self._wanted.pop(name, None)
        with (
            contextlib.suppress(MiroNaming.NotFound),
            naming_errors(self.naming.endpoint, f"unbind {name}"),
        ):
            self._registry.unbind_as(name, self.owner)

    def stop(self) -> None:
        """Stop renewing and unbind every name (a naming service that does not answer is not
        waited for)."""
        with self._lock:
            self._stop.set()
            names, self._held = list(self._held), {}
            self._wanted.clear()
        if self._thread is not None:  # its socket must be closed by no one else while in use
            self._thread.join(RENEW_TIMEOUT + BIND_TIMEOUT + 1)
        for name in names:
            with contextlib.suppress(SystemException, MiroNaming.NotFound):
                self._registry.unbind_as(name, self.owner)

    @property
    def started(self) -> bool:
        return self._thread is not None

    # ---- the renewing thread ------------------------------------------------------------------

    def _start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="miro-lease", daemon=True)
            self._thread.start()

    def _want(self, entry: MiroNaming.Entry, holder: str, how: str) -> None:
        now = time.monotonic()
        with self._lock:
            if self._stop.is_set():
                return
            was_held = self._held.pop(entry.name, None) is not None
            known = self._wanted.get(entry.name)
            if known is None or known.holder != holder:
                self._wanted[entry.name] = _Wanted(entry, holder, now, now)
        if was_held:
            self._held_changed()
        if known is not None and known.holder == holder:
            return
        _log.warning(
            "%s %s %s: this server keeps trying to bind it (every %g s) and serves it under no "
            "name meanwhile",
            entry.name,
            how,
            holder,
            RETRY_HELD,
        )
        self._start()

    def _held_changed(self) -> None:
        if self.on_held_changed is not None:
            self.on_held_changed()

    def _loop(self) -> None:
        registry = self.naming.registry_stub(self._invoker, RENEW_TIMEOUT, owner=True)
        next_renewal = time.monotonic() + self.lease / 3
        failing = False
        while True:
            with self._lock:
                wanted = bool(self._wanted)
            wait = max(0.0, next_renewal - time.monotonic())
            if self._stop.wait(min(wait, RETRY_HELD) if wanted else wait):
                return
            try:
                if time.monotonic() >= next_renewal:
                    next_renewal = time.monotonic() + self.lease / 3
                    self._renew(registry)
                self._bind_wanted(registry)
            except SystemException as e:
                if not failing:
                    _log.warning("cannot renew names: %s", e)
                failing = True
                continue
            if failing:
                _log.notice("the naming service answers again: names renewed")
                failing = False

    def _renew(self, registry: MiroNaming.Registry) -> None:
        with self._lock:
            names = list(self._held)
        if not names:
            return
        # The naming service says, name by name, which it does not hold for this run: those
        # are bound again, unless a newer run of this service took them over.
        for name in registry.renew_as(self.owner, names, self.lease_ms):
            with self._lock:
                entry = self._held.get(name)
            if entry is None:  # removed meanwhile
                continue
            try:
                registry.bind_as(entry, self.owner, self.lease_ms, False)
            except MiroNaming.AlreadyBound as e:
                self._want(entry, e.holder, "was taken by")
                continue
            _log.notice("bound %s again in the naming service", name)

    def _bind_wanted(self, registry: MiroNaming.Registry) -> None:
        now = time.monotonic()
        with self._lock:
            wanted = list(self._wanted.values())
        for w in wanted:
            try:
                registry.bind_as(w.entry, self.owner, self.lease_ms, False)
            except MiroNaming.AlreadyBound as e:
                if now - w.told >= REMIND_EVERY or e.holder != w.holder:
                    w.told, w.holder = now, e.holder
                    _log.warning(
                        "%s is still held by %s (for %.0f s): this server keeps trying",
                        w.entry.name,
                        e.holder,
                        now - w.since,
                    )
                continue
            with self._lock:
                if self._stop.is_set() or self._wanted.pop(w.entry.name, None) is None:
                    stale = True
                else:
                    self._held[w.entry.name] = w.entry
                    stale = False
            if stale:  # stopped, or removed meanwhile: leave nothing behind
                with contextlib.suppress(SystemException, MiroNaming.NotFound):
                    registry.unbind_as(w.entry.name, self.owner)
                continue
            self._held_changed()
            # Said as loudly as the warning that it was held, so that whoever saw that one
            # sees this one too.
            _log.warning(
                "bound %s in the naming service after %.1f s: it is this server's now",
                w.entry.name,
                now - w.since,
            )
