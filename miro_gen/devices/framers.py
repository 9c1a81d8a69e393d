"""Framers: cut the byte stream of a device into messages, whatever the reads' boundaries.

Each framer keeps what it has not framed yet between `feed()` calls, so a message split across
reads is framed once it is complete. Bytes that cannot belong to a message (noise before a start
delimiter, a line longer than the limit) are dropped and counted in `discarded`, never fatal.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

DEFAULT_MAX_LENGTH = 4096  # bytes a message may have before the framer gives up on it


class Framer(ABC):
    """Turns arbitrary chunks of bytes into complete messages."""

    def __init__(self, max_length: int = DEFAULT_MAX_LENGTH) -> None:
        if max_length <= 0:
            raise ValueError("max_length must be positive")
        self.max_length = max_length
        self.discarded = 0  # bytes dropped: noise, or messages over max_length
        self._buffer = bytearray()

    @abstractmethod
    def feed(self, data: bytes) -> list[bytes]:
        """The messages that `data` completes, in order."""

    def reset(self) -> None:
        """Forget a partial message (after the device reconnected)."""
        self.discarded += len(self._buffer)
        self._buffer.clear()

    def _drop(self, n: int) -> None:
        self.discarded += n
        del self._buffer[:n]


class LineFramer(Framer):
    """Messages end with `terminator` (default LF); the terminator and a trailing CR are not part
    of the message. Empty lines are skipped."""

    def __init__(self, terminator: bytes = b"\n", max_length: int = DEFAULT_MAX_LENGTH) -> None:
        super().__init__(max_length)
        if not terminator:
            raise ValueError("the terminator must not be empty")
        self.terminator = terminator

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        out: list[bytes] = []
        while True:
            end = self._buffer.find(self.terminator)
            if end < 0:
                if len(self._buffer) > self.max_length:  # no end in sight: drop what is there
                    self._drop(len(self._buffer))
                return out
            line = bytes(self._buffer[:end]).rstrip(b"\r")
            del self._buffer[: end + len(self.terminator)]
            if len(line) > self.max_length:
                self.discarded += len(line)
            elif line:
                out.append(line)


class DelimitedFramer(Framer):
    """Messages start with `start` and end with `end` (both kept in the message, as NMEA's `$`
    and CR LF are); bytes outside a message are dropped. A new `start` before the `end` abandons
    the partial message (a device that restarted mid-message)."""

    def __init__(self, start: bytes, end: bytes, max_length: int = DEFAULT_MAX_LENGTH) -> None:
        super().__init__(max_length)
        if not start or not end:
            raise ValueError("the start and end delimiters must not be empty")
        self.start = start
        self.end = end

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        out: list[bytes] = []
        while True:
            begin = self._buffer.find(self.start)
            if begin < 0:  # keep a tail that may be the beginning of `start`
                keep = len(self.start) - 1
                self._drop(max(0, len(self._buffer) - keep))
                return out
            self._drop(begin)
            end = self._buffer.find(self.end, len(self.start))
            restart = self._buffer.find(self.start, len(self.start))
            if restart >= 0 and (end < 0 or restart < end):
                self._drop(restart)
                continue
            if end < 0:
                if len(self._buffer) > self.max_length:
                    self._drop(len(self._buffer))
                return out
            stop = end + len(self.end)
            if stop > self.max_length:
                self._drop(stop)
                continue
            out.append(bytes(self._buffer[:stop]))
            del self._buffer[:stop]


class FixedLengthFramer(Framer):
    """Every message is `length` bytes."""

    def __init__(self, length: int) -> None:
        super().__init__(length)
        self.length = length

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        n = len(self._buffer) // self.length * self.length
        out = [bytes(self._buffer[i : i + self.length]) for i in range(0, n, self.length)]
        del self._buffer[:n]
        return out


class LengthPrefixedFramer(Framer):
    """Messages carry their length: a `size`-byte unsigned integer (`byteorder`) at `offset`
    from the message's start, counting the bytes after the length field. `adjust` is added for
    devices that count otherwise (-2 for a two-byte field that counts itself, +2 for a checksum
    it leaves out). An optional `sync` prefix, searched for, marks each message's start; without
    one, a length that cannot be right drops a byte at a time until one can."""

    def __init__(
        self,
        size: int = 2,
        *,
        offset: int = 0,
        byteorder: str = "big",
        adjust: int = 0,
        sync: bytes = b"",
        max_length: int = DEFAULT_MAX_LENGTH,
    ) -> None:
        super().__init__(max_length)
        if size not in (1, 2, 4) or offset < 0 or byteorder not in ("big", "little"):
            raise ValueError("size is 1, 2 or 4; offset >= 0; byteorder 'big' or 'little'")
        self.size = size
        self.offset = offset
        self.byteorder = byteorder
        self.adjust = adjust
        self.sync = sync

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        out: list[bytes] = []
        header = self.offset + self.size
        while True:
            if self.sync:
                at = self._buffer.find(self.sync)
                if at < 0:
                    self._drop(max(0, len(self._buffer) - (len(self.sync) - 1)))
                    return out
                self._drop(at)
            if len(self._buffer) < header:
                return out
            field = bytes(self._buffer[self.offset : header])
            total = header + int.from_bytes(field, self.byteorder) + self.adjust  # type: ignore[arg-type]
            if total < header or total > self.max_length:  # a corrupt length: resynchronise
                self._drop(len(self.sync) or 1)
                continue
            if len(self._buffer) < total:
                return out
            out.append(bytes(self._buffer[:total]))
            del self._buffer[:total]
