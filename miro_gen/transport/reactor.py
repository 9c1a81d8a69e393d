"""The reactor: one thread that dispatches ZeroMQ sockets, file descriptors and timers.

Like ACE's reactor in Miro, a process has one, and everything that reacts to input runs on it:
a socket or descriptor becomes readable and its handler runs; a timer expires and its handler
runs. Handlers must not block (servants run on the server's own threads, never here).
Other threads hand work to the reactor with `call_soon`, which wakes it through a socket pair;
a ZeroMQ socket must only be used by the thread that owns it, so this is how they reach it.
One exception, for a sender that cannot wait for a turn (a log player's events, due to the
tenth of a millisecond): a *shared* socket (`register_shared`) is used by whichever thread
holds its lock, the reactor among them. ZeroMQ allows a socket to pass between threads behind
a full memory barrier, which the lock is; the reactor never touches it without the lock (it
polls the socket's ZMQ_FD, not the socket), and closes it under the lock.

A handler that raises is logged (category MIRO) and the reactor goes on: one bad handler must
not stop a service.

Timers run on the reactor's clock (`miro_gen.clock`): wall time by default; a log player's
replayed time in a process started with `--clock log`, so that periods are periods of log time.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import math
import signal
import socket
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import zmq

from miro_gen.clock import Clock
from miro_gen.log import logger

_log = logger("MIRO")

# What can be registered: a ZeroMQ socket, a file descriptor, or an object with fileno().
Source = Any
# The lock of a shared socket (`Reactor.register_shared`): a `threading.Lock`.
LockLike = contextlib.AbstractContextManager[object]
TimerHandler = Callable[[Any], object]


class _Timer:
    __slots__ = ("arg", "cancelled", "due", "handler", "id", "interval")

    def __init__(self, timer_id: int, due: float, interval: float, handler: Any, arg: Any) -> None:
        self.id = timer_id
        self.due = due
        self.interval = interval
        self.handler = handler
        self.arg = arg
        self.cancelled = False

    def __lt__(self, other: _Timer) -> bool:
        return (self.due, self.id) < (other.due, other.id)


class Reactor:
    """Dispatches sockets, descriptors and timers on the thread that calls `run()`."""

    def __init__(self, context: zmq.Context[Any] | None = None, clock: Clock | None = None) -> None:
        self.context = context if context is not None else zmq.Context.instance()
        self.clock = clock if clock is not None else Clock()
        self._timer_time = self.clock.timer_time
        self._poller = zmq.Poller()
        self._handlers: dict[Any, Callable[[], object]] = {}
        self._shared: dict[zmq.Socket[Any], tuple[int, LockLike]] = {}  # socket: its FD, lock
        self._timers: list[_Timer] = []
        self._timer_by_id: dict[int, _Timer] = {}
        self._ids = itertools.count(1)
        self._calls: deque[tuple[Callable[..., object], tuple[Any, ...]]] = deque()
        self._lock = threading.Lock()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._woken = False
        self._poller.register(self._wake_r.fileno(), zmq.POLLIN)
        self._running = False
        self._stopping = False
        self._thread: threading.Thread | None = None
        self._closed = False
        self.clock.add_listener(self._clock_changed)

    # ---- sockets and descriptors ---------------------------------------------------------------

    def register(self, source: Source, handler: Callable[[], object]) -> None:
        """Call `handler()` whenever `source` (a ZeroMQ socket, a file descriptor or an object
        with `fileno()`) has input. Call from the reactor thread, or before `run()`."""
        key = _key(source)
        self._handlers[key] = handler
        self._poller.register(key, zmq.POLLIN)

    def register_shared(
        self, socket: zmq.Socket[Any], lock: LockLike, handler: Callable[[], object]
    ) -> None:
        """Call `handler()` whenever `socket`, which other threads use too (each holding
        `lock`), may have input: its ZMQ_FD signals. That descriptor signals once for any
        number of messages and is reset by whichever thread uses the socket next, so whoever
        uses it must look at ZMQ_EVENTS after each use (under the lock) and hand input it
        finds to the reactor (`call_soon(handler)`). The handler takes the lock itself.
        `close()` closes the socket under the lock. Call from the reactor thread, or before
        `run()`."""
        with lock:
            fd = int(socket.getsockopt(zmq.FD))
        self._shared[socket] = (fd, lock)
        self._handlers[fd] = handler
        self._poller.register(fd, zmq.POLLIN)

    def unregister(self, source: Source) -> None:
        shared = self._shared.pop(source, None) if isinstance(source, zmq.Socket) else None
        key = _key(source) if shared is None else shared[0]
        if self._handlers.pop(key, None) is not None:
            self._poller.unregister(key)

    # ---- timers ---------------------------------------------------------------------------------

    def schedule_timer(self, delay: float, interval: float, handler: Any, arg: Any = None) -> int:
        """Call `handler(arg)` (or `handler.handle_timeout(arg)`, as ACE does) after `delay`
        seconds, then every `interval` seconds if `interval` > 0. Returns the timer's id for
        `cancel_timer`. Safe from any thread. A periodic timer keeps its rate: a late run does
        not push the next ones back, and runs missed entirely are skipped, not bunched.
        Seconds are those of the reactor's clock (log seconds under `--clock log`)."""
        if delay < 0 or interval < 0 or math.isnan(delay) or math.isnan(interval):
            raise ValueError("timer delay and interval must be zero or more seconds")
        fn = getattr(handler, "handle_timeout", handler)
        if not callable(fn):
            raise TypeError("a timer handler is a callable or has handle_timeout(arg)")
        timer = _Timer(next(self._ids), self._timer_time() + delay, interval, fn, arg)
        with self._lock:
            self._timer_by_id[timer.id] = timer
            heapq.heappush(self._timers, timer)
        self._wake()
        return timer.id

    def cancel_timer(self, timer_id: int) -> bool:
        """Stop a timer; whether it was still scheduled. Safe from any thread."""
        with self._lock:
            timer = self._timer_by_id.pop(timer_id, None)
        if timer is None:
            return False
        timer.cancelled = True
        return True

    def _clock_changed(self, jump: float) -> None:
        """The clock jumped (or changed its pace): move the timers with it and look again."""
        if jump:
            with self._lock:
                for timer in self._timers:
                    timer.due += jump  # the same shift for all: the heap stays ordered
        self._wake()

    # ---- calls from other threads ---------------------------------------------------------------

    def call_soon(self, fn: Callable[..., object], *args: Any) -> None:
        """Run `fn(*args)` on the reactor thread, soon, in the order of the calls."""
        self._calls.append((fn, args))
        self._wake()

    def in_reactor_thread(self) -> bool:
        return self._thread is threading.current_thread()

    # ---- running --------------------------------------------------------------------------------

    def run(self) -> None:
        """Dispatch until `stop()`."""
        if self._running:
            raise RuntimeError("the reactor is already running")
        self._running = True
        self._stopping = False
        self._thread = threading.current_thread()
        # A signal may be delivered to any thread, and Python runs its handler only when the
        # main thread runs Python code: the wake-up socket makes a signal end the poll.
        old_fd = None
        if self._thread is threading.main_thread():
            old_fd = signal.set_wakeup_fd(self._wake_w.fileno(), warn_on_full_buffer=False)
        try:
            while not self._stopping:
                self._turn()
        finally:
            if old_fd is not None:
                signal.set_wakeup_fd(old_fd)
            self._running = False
            self._thread = None

    def run_in_thread(self, name: str = "miro-reactor") -> threading.Thread:
        """Start `run()` on a daemon thread of its own; the thread."""
        ready = threading.Event()

        def main() -> None:
            self.call_soon(ready.set)
            self.run()

        t = threading.Thread(target=main, name=name, daemon=True)
        t.start()
        ready.wait(5)
        return t

    def stop(self) -> None:
        """Make `run()` return after the current turn. Safe from any thread."""
        self._stopping = True
        self._wake()

    @property
    def closed(self) -> bool:
        """Whether `close()` has been called: nothing runs on this reactor any more."""
        return self._closed

    @property
    def stopping(self) -> bool:
        """Whether `run()` is to return: a handler with a long queue of work may stop early."""
        return self._stopping

    def close(self) -> None:
        """After `run()` has returned: close the ZeroMQ sockets still registered (their owners,
        suppliers and consumers, live on this thread) and the wake-up sockets. A context with
        open sockets would otherwise hang whoever terminates it."""
        if not self._closed:
            self._closed = True
            sockets = [k for k in self._handlers if isinstance(k, zmq.Socket) and not k.closed]
            shared = list(self._shared.items())
            for s, (_, lock) in shared:  # under their lock: other threads may use them
                with lock, contextlib.suppress(zmq.ZMQError):
                    s.disable_monitor()
            for s in sockets:  # first stop the monitors: libzmq blocks on a closed one's events
                with contextlib.suppress(zmq.ZMQError):
                    s.disable_monitor()
            for s in sockets:
                s.close(0)
            for s, (_, lock) in shared:
                with lock:
                    s.close(0)
            self._shared.clear()
            self._handlers.clear()
            self._wake_r.close()
            self._wake_w.close()

    def _turn(self) -> None:
        timeout = self._run_due_timers()
        if self._calls or self._stopping:
            timeout = 0
        events = self._poller.poll(timeout)
        for key, _ in events:
            if key == self._wake_r.fileno():
                self._drain_wakeups()
                continue
            handler = self._handlers.get(key)
            if handler is not None:
                self._safely(handler)
        while self._calls:
            fn, args = self._calls.popleft()
            self._safely(fn, *args)

    def _run_due_timers(self) -> int | None:
        """Run the timers that are due; milliseconds until the next one (None: no timer)."""
        now = self._timer_time()
        due: list[_Timer] = []
        with self._lock:
            while self._timers and (self._timers[0].cancelled or self._timers[0].due <= now):
                timer = heapq.heappop(self._timers)
                if timer.cancelled:
                    continue
                due.append(timer)
                if timer.interval > 0:
                    missed = math.floor((now - timer.due) / timer.interval)
                    timer.due += (missed + 1) * timer.interval
                    heapq.heappush(self._timers, timer)
                else:
                    self._timer_by_id.pop(timer.id, None)
            next_due = self._timers[0].due if self._timers else None
        for timer in due:
            if not timer.cancelled:
                self._safely(timer.handler, timer.arg)
        if next_due is None:
            return None
        wait = self.clock.real_delay(next_due - self._timer_time())
        if wait is None:  # the clock stands still: a change of it wakes the reactor
            return None
        return max(0, math.ceil(wait * 1000))

    def _wake(self) -> None:
        if not self._woken:
            self._woken = True
            with contextlib.suppress(BlockingIOError, OSError):  # full (so awake) or closed
                self._wake_w.send(b"\0")

    def _drain_wakeups(self) -> None:
        # Cleared after draining: a wake-up skipped meanwhile (flag still set) needs no byte,
        # since this turn still runs the queued calls and the next one rereads the timers.
        with contextlib.suppress(BlockingIOError, OSError):
            while self._wake_r.recv(4096):
                pass
        self._woken = False

    @staticmethod
    def _safely(fn: Callable[..., object], *args: Any) -> None:
        try:
            fn(*args)
        except Exception:
            _log.exception("a reactor handler failed: %r", fn)


def _key(source: Source) -> Any:
    if isinstance(source, zmq.Socket):
        return source
    if isinstance(source, int):
        return source
    fileno = getattr(source, "fileno", None)
    if fileno is None:
        raise TypeError(f"cannot poll {source!r}: not a ZeroMQ socket, fd or file")
    return fileno()
