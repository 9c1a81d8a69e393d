"""Fragmented GIOP messages put back together, for one connection (no I/O).

GIOP 1.1 fragments follow their first part, one message at a time; GIOP 1.2 fragments name
their request, so several messages may be unfinished at once. Both ends of a connection keep
them here, counted: at most `MAX_UNFINISHED` messages per connection, and their bytes together
(`held`) at most the message limit, so that one connection cannot
hold more than one maximal message however it interleaves its fragments.

A message the server refused to take whole (its byte budget was spent: `abandon`) is
forgotten, and its later fragments are swallowed until its last one.
"""

from __future__ import annotations

from struct import Struct

from miro_gen.corba import giop
from miro_gen.corba.giop import HEADER_SIZE, GiopError, Header, MsgType

_SIZE = (Struct("<I"), Struct(">I"))
MAX_UNFINISHED = 8  # fragmented messages unfinished at once on one connection
_GIOP11 = -1  # the key of GIOP 1.1's one unfinished message


class _Partial:
    __slots__ = ("data", "wire")

    def __init__(self, msg: bytes | bytearray) -> None:
        self.data = bytearray(msg)
        self.wire = len(msg)  # bytes it came in, fragment headers included


class Reassembly:
    """The unfinished fragmented messages of one connection."""

    def __init__(self, max_message: int) -> None:
        self.max_message = max_message
        self._partials: dict[int, _Partial] = {}  # by request id (1.2) or _GIOP11
        self._abandoned: set[int] = set()
        self.held = 0  # bytes of the unfinished messages, reassembled

    def __len__(self) -> int:
        return len(self._partials) + len(self._abandoned)

    def key(self, h: Header, msg: bytes | bytearray) -> int:
        """Which unfinished message a first part or a Fragment belongs to."""
        if h.minor == 1:
            return _GIOP11
        return giop.decode_request_id(msg, h)

    def begin(self, h: Header, msg: bytes | bytearray) -> None:
        """The first part of a fragmented message (its More flag set)."""
        if h.type not in (MsgType.REQUEST, MsgType.REPLY) and not (
            h.minor >= 2 and h.type in (MsgType.LOCATE_REQUEST, MsgType.LOCATE_REPLY)
        ):
            raise GiopError(f"a {h.type.name} message cannot be fragmented")
        key = self.key(h, msg)
        if key in self._partials or key in self._abandoned:
            if key == _GIOP11:
                raise GiopError("a new fragmented message began before the last one ended")
            raise GiopError(f"a second fragmented message with request id {key}")
        if len(self) >= MAX_UNFINISHED:
            raise GiopError(f"more than {MAX_UNFINISHED} unfinished fragmented messages")
        self._add_held(len(msg))
        self._partials[key] = _Partial(msg)

    def add(self, h: Header, msg: bytes | bytearray) -> tuple[Header, bytearray, int] | None:
        """A Fragment: the whole message when it was the last one (its header, its bytes, not
        copied, and how many bytes its parts came in), else None."""
        key = self.key(h, msg)
        if key in self._abandoned:
            if not h.more:
                self._abandoned.discard(key)
            return None
        partial = self._partials.get(key)
        if partial is None:
            raise GiopError("a Fragment that continues no message")
        tail = memoryview(msg)[HEADER_SIZE + (0 if key == _GIOP11 else 4) :]
        self._add_held(len(tail))
        partial.data += tail
        partial.wire += len(msg)
        if h.more:
            return None
        del self._partials[key]
        self.held -= len(partial.data)
        data = partial.data
        first = giop.read_header(bytes(data[:HEADER_SIZE]))
        data[6] &= ~giop.FLAG_MORE & 0xFF
        _SIZE[0 if first.little else 1].pack_into(data, 8, len(data) - HEADER_SIZE)
        whole = first._replace(more=False, size=len(data) - HEADER_SIZE)
        return whole, data, partial.wire

    def abandon(self, key: int, more: bool) -> tuple[bytes, int]:
        """Forget the unfinished message `key` (its later fragments are swallowed while
        `more`): the first bytes of what was kept of it (b"" if nothing), and how many bytes
        it held."""
        partial = self._partials.pop(key, None)
        if more:
            if len(self) >= MAX_UNFINISHED:
                raise GiopError(f"more than {MAX_UNFINISHED} unfinished fragmented messages")
            self._abandoned.add(key)
        else:
            self._abandoned.discard(key)
        if partial is None:
            return b"", 0
        self.held -= len(partial.data)
        return bytes(partial.data[:1024]), partial.wire

    def is_abandoned(self, key: int) -> bool:
        return key in self._abandoned

    def clear(self) -> int:
        """Forget everything; how many bytes the unfinished messages came in."""
        wire = sum(p.wire for p in self._partials.values())
        self.held = 0
        self._partials.clear()
        self._abandoned.clear()
        return wire

    def _add_held(self, n: int) -> None:
        if self.held + n > self.max_message + HEADER_SIZE:
            raise GiopError(
                f"fragmented messages beyond the limit of {self.max_message} bytes together"
            )
        self.held += n
