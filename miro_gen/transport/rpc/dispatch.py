"""Leader/followers: the threads that take turns owning a server's ROUTER socket.

TAO's default server concurrency, fitted to ZeroMQ, where a socket must be used by one thread
at a time. One thread, the *leader*, waits on the socket, receives a request and runs its
servant itself: no hand-off to another thread on the way in, and the reply goes out on the
same thread that computed it. Meanwhile nobody waits on the socket, so a servant that blocks
(waits for the next reading, calls a service that calls back) must not keep the leadership:

* a watchdog thread hands the leadership to another thread (an idle follower, or a new one)
  when a servant has run for `TAKEOVER` seconds; the operation is then known to block, and
  from then on the leader hands its leadership over *before* running it, as TAO does;
* a thread whose servant returns after it lost the leadership hands the reply to the current
  leader (through a queue and a wake-up socket), then serves queued requests or waits, idle,
  to lead again;
* tasks marked quick (`@nonblocking`) always run on the leader, never handed over.

The leader waits in a plain blocking receive on the ROUTER, the cheapest wait ZeroMQ has (a
poll of two sources costs a tenth of a loopback round trip). Whatever else must reach it
arrives on that same socket: each thread that hands back a reply, or wakes the leader to close,
sends it over an inproc connection to the ROUTER, prefixed with a random token that remote
peers cannot know.

At most `workers` threads run servants at once; beyond that, requests wait in a queue bounded
in requests and bytes (the caller is told TRANSIENT when it is full) and those whose callers
have stopped waiting by the time a thread is free are not run. Sockets change hands only under
the dispatcher's lock, the memory barrier ZeroMQ asks for.
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Hashable, Sequence
from typing import Any, Protocol, cast

import zmq
from zmq.backend import Socket as _Socket

from miro_gen.log import logger
from miro_gen.transport.buffers import keep_large_buffers
from miro_gen.transport.rpc.frames import ZERO_COPY_MIN, body_of

_log = logger("MIRO")

TAKEOVER = 0.005  # seconds a servant may keep the leader before another thread takes over
WATCH_IDLE = 1.0  # seconds without servants after which the watchdog sleeps until the next one
STOPPING = "is stopping"  # why a draining server refuses a request
CLOSE_LINGER_MS = 500  # how long replies sent during a drain may take to leave
# Seconds a drained server keeps its connections open after answering the calls it was
# serving: a reply that arrives just before its connection closes is dropped by the caller's
# ZeroMQ (IMMEDIATE, no reconnection: invoker.py) unless the caller's thread has read it by
# then, which on a loaded machine it may not have.
REPLY_GRACE = 0.5

_send, _recv = _Socket.send, _Socket.recv  # without pyzmq's Python wrappers: a call's cost
_NOBLOCK = int(zmq.NOBLOCK)
_MORE = int(zmq.SNDMORE) | _NOBLOCK

Frames = list[bytes]


class Task(Protocol):
    """A request whose servant is to run."""

    kind: Hashable  # what the dispatcher learns "may block" about: (servant class, operation)
    quick: bool  # @nonblocking: run by the leader, never handed over
    size: int  # bytes it holds while it waits

    def late(self) -> bool:
        """Whether its caller has stopped waiting (a queued task is then not run)."""
        ...

    def run(self) -> Frames | None:
        """Run it; the reply's frames (None: nothing to send). Never raises."""
        ...

    def refuse(self, why: str = "is overloaded") -> Frames | None:
        """The reply that says the server will not run it now (TRANSIENT, completed NO): it
        has too much to do, or is stopping."""
        ...


# What ZeroMQ knows of the connection a message came on: its peer address and the user id the
# admission thread gave it (transport.rpc.caller); asked for only by dispatchers that identify.
Peer = tuple[str, str]

# What the owner of the socket makes of a message (and its peer, when asked for): a task to
# run, frames to send back at once, or None (dropped, or nothing to answer).
Receive = Callable[[Frames, "Peer | None"], "Task | Frames | None"]


def _peer(frame: zmq.Frame) -> Peer:
    try:
        address = str(frame.get("Peer-Address"))
    except zmq.ZMQError:
        address = ""
    try:
        user = str(frame.get("User-Id"))
    except zmq.ZMQError:  # the admission thread gave none (no key)
        user = ""
    return address, user


class _Closed(Exception):
    pass


class _Worker:
    __slots__ = ("link", "number", "wake")

    def __init__(self, number: int) -> None:
        self.number = number
        self.wake = threading.Lock()  # held: released to wake the thread
        self.wake.acquire()
        self.link: zmq.Socket[Any] | None = None  # its inproc DEALER to the socket, once used


class Dispatcher:
    """Serves `socket` (a ROUTER) with up to `workers` threads running servants at once;
    `receive` turns each message (and, when `identify`, its peer) into a task or an immediate
    reply."""

    def __init__(
        self,
        socket: zmq.Socket[Any],
        receive: Receive,
        workers: int,
        max_pending: int,
        max_pending_bytes: int = 1 << 62,
        identify: bool = False,
    ) -> None:
        self.socket = socket
        self._receive = receive
        self._identify = identify
        self._workers = max(1, workers)
        self._max_pending = max_pending
        self._max_pending_bytes = max_pending_bytes
        self._pending_bytes = 0
        self._lock = threading.Lock()
        self._numbers = itertools.count(1)
        self._threads = 0
        self._serving = 0  # threads running servants (the leader's own included)
        self._idle: list[_Worker] = []
        self._pending: deque[Task] = deque()
        self._may_block: set[Hashable] = set()
        self._inline: tuple[float, Hashable, _Worker] | None = None  # the leader's servant
        self._last_inline = 0.0
        self._watch = threading.Lock()
        self._watch.acquire()
        self._watch_asleep = False
        self._watchdog: threading.Thread | None = None
        self._closed = False
        self._draining = False  # stopping: requests are refused, running ones finish
        self._owed = 0  # replies handed to the leader and not sent yet
        self._drained = threading.Condition(self._lock)  # notified when nothing is owed
        self._socket_closed = threading.Event()
        self._token = os.urandom(16)  # begins what other threads send the leader
        self._inproc = f"inproc://miro-dispatch-{id(self):x}-{self._token.hex()[:8]}"
        socket.bind(self._inproc)
        self._current = threading.local()
        self._leader: _Worker | None = None
        with self._lock:
            self._spawn_leader()

    # ---- threads -------------------------------------------------------------------------------

    def _spawn_leader(self) -> None:
        """A new thread, to lead (the caller holds the lock)."""
        worker = self._leader = _Worker(next(self._numbers))
        self._threads += 1
        name = f"miro-worker-{worker.number}"
        threading.Thread(target=self._main, args=(worker,), name=name, daemon=True).start()

    def _main(self, me: _Worker) -> None:
        self._current.worker = me
        try:
            while True:
                if self._leader is me:
                    self._lead(me)
                task = self._next(me)
                if task is not None:
                    self._finished(me, self._run(task))
        except _Closed:
            pass
        except Exception:  # pragma: no cover - a defect: say so, keep the process up
            _log.exception("a dispatch thread failed")
        finally:
            if me.link is not None:
                me.link.close(0)
            with self._lock:
                self._threads -= 1

    def _next(self, me: _Worker) -> Task | None:
        """A queued task to run, or None once this thread is to lead; waits, idle, meanwhile."""
        while True:
            with self._lock:
                if self._closed:
                    raise _Closed
                if self._leader is me:
                    return None
                while self._pending and not self._draining:
                    task = self._pending.popleft()
                    self._pending_bytes -= task.size
                    if task.late():
                        _log.notice("skipped a request: its caller stopped waiting")
                        continue
                    self._serving += 1
                    return task
                self._idle.append(me)
            me.wake.acquire()

    def _promote(self) -> None:
        """Give the leadership to an idle thread, or a new one (the caller holds the lock)."""
        if self._idle:
            self._leader = self._idle.pop()
            self._leader.wake.release()
        else:
            self._spawn_leader()

    # ---- the leader ----------------------------------------------------------------------------

    def _lead(self, me: _Worker) -> None:
        """Serve the socket while this thread is the leader."""
        token = self._token
        while True:
            if self._closed:
                self._close_socket()
                raise _Closed
            parts, last = self._recv_message()
            if len(parts) > 1 and parts[1] == token:  # from a thread of ours
                if len(parts) > 2:
                    self._send(parts[2:])  # a reply handed back
                    self._paid()
                elif self._draining:
                    self._refuse_pending()
                continue
            if type(parts[-1]) is memoryview:  # a large request: skeletons decode bytes
                parts[-1] = bytes(parts[-1])
            out = self._receive(cast(Frames, parts), _peer(last) if self._identify else None)
            if out is None:
                continue
            if isinstance(out, list):
                self._send(out)
            elif self._draining:
                self._send(out.refuse(STOPPING))
                self._refuse_pending()
            elif out.quick:
                self._send(self._run(out))
            elif self._start(out, me) and not self._finished(me, self._run(out)):
                return  # another thread leads now

    def _start(self, task: Task, me: _Worker) -> bool:
        """Whether the leader is to run `task` now; else it is queued, or refused when the
        queue is full."""
        with self._lock:
            if self._serving < self._workers:
                self._serving += 1
                if task.kind in self._may_block:
                    self._promote()  # known to block: hand over first
                else:
                    self._inline = (time.monotonic(), task.kind, me)
                    self._last_inline = self._inline[0]
                    self._wake_watchdog()
                return True
            if (
                len(self._pending) < self._max_pending
                and self._pending_bytes + task.size <= self._max_pending_bytes
            ):
                self._pending.append(task)
                self._pending_bytes += task.size
                return False
        self._send(task.refuse())
        return False

    def _finished(self, me: _Worker, frames: Frames | None) -> bool:
        """After running a task: send its reply, or hand it to the leader; whether this thread
        still leads."""
        with self._lock:
            self._serving -= 1
            if self._inline is not None and self._inline[2] is me:
                self._inline = None
            leading = self._leader is me
            if frames is not None and not leading:
                self._owed += 1  # until the leader has sent it
            elif not self._serving and not self._owed:
                self._drained.notify_all()
        if frames is not None:
            if leading:
                self._send(frames)
            else:
                self._tell_leader(me, frames)
        return leading

    # ---- the watchdog --------------------------------------------------------------------------

    def _wake_watchdog(self) -> None:
        """(lock held) Start the watchdog, or wake it from its idle sleep."""
        if self._watchdog is None:
            self._watchdog = threading.Thread(
                target=self._watch_loop, name="miro-watchdog", daemon=True
            )
            self._watchdog.start()
        elif self._watch_asleep:
            self._watch_asleep = False
            self._watch.release()

    def _watch_loop(self) -> None:
        while True:
            with self._lock:
                if self._closed:
                    return
                now = time.monotonic()
                inline = self._inline
                if inline is not None and now - inline[0] >= TAKEOVER:
                    self._inline = None
                    if self._leader is inline[2]:
                        self._may_block.add(inline[1])
                        self._promote()
                        _log.debug("%s blocks: handed over before it runs from now on", inline[1])
                asleep = self._inline is None and now - self._last_inline > WATCH_IDLE
                self._watch_asleep = asleep
            if asleep:
                self._watch.acquire()
            else:
                self._watch.acquire(timeout=TAKEOVER)

    # ---- socket I/O (by the leader only) -------------------------------------------------------

    def _recv_message(self) -> tuple[list[bytes | memoryview], zmq.Frame]:
        """A message's frames, and the last one (which knows the connection it came on). The
        last, a body, is a view over the frame when large (`frames.body_of`): a reply handed
        back by another thread is forwarded without a copy."""
        sock = self.socket
        frame = _recv(sock, 0, False)
        parts: list[bytes | memoryview] = []
        while frame.more:
            parts.append(frame.bytes)
            frame = _recv(sock, _NOBLOCK, False)
        parts.append(body_of(frame))
        return parts, frame

    def _send(self, frames: Sequence[bytes | memoryview] | None) -> None:
        if frames is None or self._closed:
            return
        sock = self.socket
        try:
            for frame in frames[:-1]:
                _send(sock, frame, _MORE)
            body = frames[-1]
            if len(body) < ZERO_COPY_MIN:
                _send(sock, body, _NOBLOCK)
            else:  # a large result goes without a copy
                keep_large_buffers()
                _send(sock, body, _NOBLOCK, False)
        except zmq.ZMQError as e:  # the caller is gone: nobody to tell
            _log.notice("could not send a reply: %s", e)

    def _tell_leader(self, me: _Worker | None, frames: Frames) -> None:
        """Send `frames` (a reply to forward, or nothing: a wake-up) to the leader, through
        the inproc link of this thread (`me`; None: a thread of no worker, once)."""
        if self._socket_closed.is_set():
            return
        link = me.link if me is not None else None
        if link is None:
            link = self.socket.context.socket(zmq.DEALER)
            link.setsockopt(zmq.LINGER, 0 if me is not None else 1000)  # a one-off: delivered
            link.connect(self._inproc)
            if me is not None:
                me.link = link
        try:
            link.send_multipart([self._token, *frames], zmq.NOBLOCK)
        except zmq.ZMQError as e:
            if not frames and self._closed:
                # A wake-up to close: the leader, woken meanwhile by an earlier message (a
                # drain's), saw `_closed` first and closed its socket; nobody is left to wake.
                _log.debug("no leader to wake: %s", e)
            else:  # pragma: no cover - an inproc queue of 1000 replies is full
                _log.warning("could not hand a reply to the leader: %s", e)
        finally:
            if me is None:
                link.close()  # with its linger: the wake-up is still delivered

    @staticmethod
    def _run(task: Task) -> Frames | None:
        try:
            return task.run()
        except Exception:  # pragma: no cover - tasks never raise; a defect if one does
            _log.exception("a request failed")
            return None

    # ---- closing -------------------------------------------------------------------------------

    def drain(self, timeout: float) -> bool:
        """Stop taking requests (each one that comes, or waits in the queue, is answered
        TRANSIENT, completed NO: its caller may go elsewhere) and wait up to `timeout` seconds
        for the servants that run to finish, their replies sent, then REPLY_GRACE seconds for
        their callers to read them; whether they all did."""
        with self._lock:
            self._draining = True
            answering = self._serving + self._owed  # calls answered while draining
        self._tell_leader(getattr(self._current, "worker", None), [])  # refuse the queue
        with self._lock:
            done = self._drained.wait_for(lambda: not self._serving and not self._owed, timeout)
        if done and answering:  # their callers read the replies before the connections close
            time.sleep(REPLY_GRACE)
        return done

    def _paid(self) -> None:
        """(leader) A reply handed back has been sent."""
        with self._lock:
            self._owed -= 1
            if not self._serving and not self._owed:
                self._drained.notify_all()

    def _refuse_pending(self) -> None:
        """(leader) Answer every queued request TRANSIENT: the server is stopping."""
        with self._lock:
            pending, self._pending = list(self._pending), deque()
            self._pending_bytes = 0
        for task in pending:
            self._send(task.refuse(STOPPING))

    def close(self, timeout: float = 2.0) -> None:
        """Stop serving: the leader closes the socket (at once, or when its servant returns);
        idle threads end. Waits up to `timeout` seconds for the socket to be closed."""
        with self._lock:
            self._closed = True
            idle, self._idle = self._idle, []
            if self._watch_asleep:
                self._watch_asleep = False
                self._watch.release()
        for worker in idle:
            worker.wake.release()
        me = getattr(self._current, "worker", None)
        self._tell_leader(me, [])
        if me is None:  # not from a servant of ours, which would wait for itself
            self._socket_closed.wait(timeout)

    def _close_socket(self) -> None:
        # After a drain, the replies just sent still go out (while the process lives).
        self.socket.close(CLOSE_LINGER_MS if self._draining else 0)
        self._socket_closed.set()
