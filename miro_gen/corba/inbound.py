"""What one server connection receives, made into whole GIOP messages under a byte budget (no
I/O: bytes in, messages out).

Every message is weighed when its 12-byte header has come, before its body is read: it is
taken only if the server's `Budget` (shared by all connections) has room for it, and, when it
is one part of a fragmented message, if the connection's unfinished messages stay within one
message limit (`fragments.Reassembly`). A message taken reserves twice its size (it is copied
once on its way to the servant) plus `OVERHEAD`, from its header until the server gives the
reservation back, after its reply. A message refused is read and thrown away as it comes,
keeping only its first `HEAD` bytes, from which the server answers the request (TRANSIENT): a
refusal costs no memory and leaves the connection usable. The bytes of every message are
counted against `max_message` before any is kept.

Control messages of at most `SMALL` bytes (LocateRequest, CancelRequest, CloseConnection,
MessageError) are answered at once and never queued: they take nothing from the budget.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from miro_gen.corba import giop
from miro_gen.corba.connection import NotGiop, is_zmtp
from miro_gen.corba.fragments import Reassembly
from miro_gen.corba.giop import HEADER_SIZE, GiopError, Header, MsgType

SMALL = 64 << 10  # a message this size or smaller may use the budget's reserve
OVERHEAD = 1024  # bytes charged per message beyond its own: the objects that carry it
HEAD = 1024  # bytes kept of a refused message, to answer it
_CONTROL = (
    MsgType.CANCEL_REQUEST,
    MsgType.LOCATE_REQUEST,
    MsgType.CLOSE_CONNECTION,
    MsgType.MESSAGE_ERROR,
)
_RECV_HEADER = 65536  # bytes asked of the socket when a header is due
_RECV_BODY = 1 << 20  # at most this many at once while a large body comes


class Budget:
    """The bytes that the messages a server holds may reserve, across its connections: those
    being read, unfinished fragmented ones, requests waiting for a worker or running, and
    replies not yet sent. `reserve` of it is kept for messages of at most `SMALL` bytes, so
    that a few large ones cannot stop small calls."""

    def __init__(self, total: int, reserve: int) -> None:
        self.total = total
        self.reserve = reserve
        self.used = 0
        self._lock = threading.Lock()

    def take(self, n: int, small: bool) -> bool:
        """Reserve `n` bytes if there is room for them."""
        limit = self.total if small else self.total - self.reserve
        with self._lock:
            if self.used + n > limit:
                return False
            self.used += n
            return True

    def force(self, n: int) -> None:
        """Count `n` bytes that exist whether there is room or not (a reply made)."""
        with self._lock:
            self.used += n

    def give(self, n: int) -> None:
        with self._lock:
            self.used -= n


@dataclass(slots=True)
class Message:
    """A whole message; `charge`: what it reserved, to be given back when it is done with.
    `data` is a bytearray when the server may reuse its bytes (a large message, not copied)."""

    header: Header
    data: bytes | bytearray
    charge: int


@dataclass(slots=True)
class Refused:
    """A message the budget had no room for, read and thrown away: `head`, its first bytes
    (header included; for a Fragment, those of the message it continued), to answer it."""

    header: Header
    head: bytes


def charge_of(size: int) -> int:
    """What a message of `size` bytes after its header reserves."""
    return 2 * (HEADER_SIZE + size) + OVERHEAD


class Inbound:
    """The bytes of one connection in, messages out (`feed`). `reserved`: what this
    connection's unfinished messages hold of the budget (given back by `release`)."""

    def __init__(self, peer: str, max_message: int, budget: Budget) -> None:
        self.peer = peer
        self.max_message = max_message
        self.budget = budget
        self.fragments = Reassembly(max_message)
        self.reserved = 0
        self._buf = bytearray()
        self._h: Header | None = None  # the message being read (or skipped)
        self._left = 0  # bytes of its body still to come
        self._charge = 0  # what it reserved (0: skipped, or free)
        self._skipping = False
        self._partial_charges: dict[int, int] = {}  # reservations of unfinished messages
        self._started = False

    @property
    def busy(self) -> bool:
        """Whether a message is part-way in (or a fragmented one unfinished)."""
        return bool(self._buf) or self._h is not None or len(self.fragments) > 0

    def want(self) -> int:
        """How many bytes to ask the socket for next."""
        if self._h is None or self._left < _RECV_HEADER:
            return _RECV_HEADER
        return min(self._left, _RECV_BODY)

    def feed(self, data: bytes) -> list[Message | Refused]:
        """The messages that `data` completes. GiopError when the peer breaks the protocol,
        NotGiop when it speaks something else."""
        if not self._started:
            self._started = True
            if is_zmtp(data):
                raise NotGiop(f"{self.peer} speaks ZeroMQ, not GIOP", zmq=True)
        n = len(data)
        if self._h is None and not self._buf and n >= HEADER_SIZE and data[:4] == giop.MAGIC:
            h = giop.whole_message_header(data)  # the common case: one whole message
            if h is not None:
                self._begin(h)
                self._h, self._left = None, 0
                if self._skipping:
                    self._skipping = False
                    return [Refused(h, data[:HEAD])]
                charge, self._charge = self._charge, 0
                self.reserved -= charge
                return [Message(h, data, charge)]
        out: list[Message | Refused] = []
        view = memoryview(data)
        pos = 0
        while pos < n:
            if self._h is None:
                take = min(HEADER_SIZE - len(self._buf), n - pos)
                self._buf += view[pos : pos + take]
                pos += take
                if len(self._buf) < HEADER_SIZE:
                    break
                self._begin(self._header(bytes(self._buf)))
                if self._skipping:
                    self._buf = bytearray(self._buf[:HEADER_SIZE])  # the head kept
            else:
                take = min(self._left, n - pos)
                if not self._skipping:
                    self._buf += view[pos : pos + take]
                elif len(self._buf) < HEAD:
                    self._buf += view[pos : pos + min(take, HEAD - len(self._buf))]
                pos += take
                self._left -= take
            if self._h is not None and self._left == 0:
                done = self._end()
                if done is not None:
                    out.append(done)
        return out

    def release(self) -> None:
        """Give back everything this connection reserved (it is closed)."""
        self.fragments.clear()
        self._partial_charges.clear()
        self.budget.give(self.reserved)
        self.reserved = 0

    # ---- one message ----------------------------------------------------------------------------

    def _header(self, head: bytes) -> Header:
        if head[:4] != giop.MAGIC:
            raise NotGiop(f"{self.peer} sent {head[:4]!r}, which is not GIOP", zmq=False)
        return giop.read_header(head)

    def _begin(self, h: Header) -> None:
        """Weigh the message whose header is `h`: take it, or skip it."""
        if h.size > self.max_message:
            raise GiopError(
                f"{self.peer} sent a {h.size}-byte message; the limit is {self.max_message}"
            )
        self._h, self._left, self._charge = h, h.size, 0
        self._skipping = False
        if h.type in _CONTROL and not h.more and h.size <= SMALL:
            return
        part = h.more or h.type == MsgType.FRAGMENT
        charge = charge_of(h.size)
        if (part and self.fragments.held + h.size > self.max_message) or not self.budget.take(
            charge, small=h.size <= SMALL
        ):
            self._skipping = True
            return
        self._charge = charge
        self.reserved += charge

    def _end(self) -> Message | Refused | None:
        h = self._h
        assert h is not None
        data, self._buf = self._buf, bytearray()
        self._h = None
        if self._skipping:
            self._skipping = False
            return self._refused(h, bytes(data))
        charge, self._charge = self._charge, 0
        if h.type == MsgType.FRAGMENT:
            key = self.fragments.key(h, data)
            whole = self.fragments.add(h, data)
            if whole is None:
                if self.fragments.is_abandoned(key) or not h.more:  # swallowed
                    self._give(charge)
                else:
                    self._partial_charges[key] = self._partial_charges.get(key, 0) + charge
                return None
            first, msg, _ = whole
            total = self._partial_charges.pop(key, 0) + charge
            self.reserved -= total
            return Message(first, msg, total)
        if h.more:
            self.fragments.begin(h, data)
            key = self.fragments.key(h, data)
            self._partial_charges[key] = charge
            return None
        self.reserved -= charge
        return Message(h, data, charge)

    def _refused(self, h: Header, head: bytes) -> Refused | None:
        """A message skipped for want of room: what the server is to answer (None: nothing,
        a later fragment of a message already refused)."""
        if h.type != MsgType.FRAGMENT and not h.more:
            return Refused(h, head)
        key = self.fragments.key(h, head)
        if h.type != MsgType.FRAGMENT:  # the first part: its fragments are swallowed
            self.fragments.abandon(key, more=True)
            return Refused(h, head)
        if self.fragments.is_abandoned(key):
            if not h.more:
                self.fragments.abandon(key, more=False)
            return None
        first, _ = self.fragments.abandon(key, more=h.more)
        if not first:
            raise GiopError("a Fragment that continues no message")
        self._give(self._partial_charges.pop(key, 0))
        return Refused(giop.read_header(first[:HEADER_SIZE]), first)

    def _give(self, n: int) -> None:
        self.reserved -= n
        self.budget.give(n)
