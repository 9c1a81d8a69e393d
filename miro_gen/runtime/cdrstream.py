"""CDR as a stream, for what is not generated: GIOP headers, IORs, TypeCodes, `any` values.

Generated codecs (`miro_gen.runtime.cdr`) encode one IDL value into a buffer that starts with a
4-byte encapsulation header; GIOP messages, object references and TypeCodes are read and written
field by field, at offsets that count from the start of a message or of an encapsulation. These
two classes do that, with the same string, sequence and length checks as the generated codecs
(they call the same functions): alignment counts from offset 0 of the buffer, so a stream over a
whole GIOP message aligns as GIOP says (relative to the start of the message header), and a
stream over an encapsulation's bytes aligns relative to the encapsulation.

`CdrOutput` always writes little-endian; `CdrInput` reads either byte order. Every read past the
end, and every length that cannot fit in what is left, raises `MARSHAL`.
"""

from __future__ import annotations

import builtins
from struct import Struct
from struct import error as StructError
from typing import Final

from miro_gen.exceptions import MARSHAL
from miro_gen.runtime.cdr import (
    BE,
    LE,
    ZEROS,
    get_length,
    get_octets,
    get_string,
    pair,
    put_length,
    put_octets,
    put_string,
)

_H: Final = pair("h")
_HU: Final = pair("H")
_L: Final = pair("i")
_LU: Final = pair("I")
_Q: Final = pair("q")
_QU: Final = pair("Q")
_F: Final = pair("f")
_D: Final = pair("d")
_B: Final = Struct("b")


class CdrOutput:
    """A little-endian CDR writer; alignment relative to the start of `buf`."""

    __slots__ = ("buf",)

    def __init__(self, buf: bytearray | None = None) -> None:
        self.buf = bytearray() if buf is None else buf

    def align(self, n: int) -> None:
        self.buf += ZEROS[-len(self.buf) & (n - 1)]

    def octet(self, v: int) -> None:
        self.buf.append(v & 0xFF)

    def boolean(self, v: bool) -> None:
        self.buf.append(1 if v else 0)

    def char(self, v: str) -> None:
        self.buf += v.encode("latin-1")

    def short(self, v: int) -> None:
        self.buf += ZEROS[len(self.buf) & 1]
        self.buf += _H[LE].pack(v)

    def ushort(self, v: int) -> None:
        self.buf += ZEROS[len(self.buf) & 1]
        self.buf += _HU[LE].pack(v)

    def long(self, v: int) -> None:
        self.buf += ZEROS[-len(self.buf) & 3]
        self.buf += _L[LE].pack(v)

    def ulong(self, v: int) -> None:
        self.buf += ZEROS[-len(self.buf) & 3]
        self.buf += _LU[LE].pack(v)

    def longlong(self, v: int) -> None:
        self.buf += ZEROS[-len(self.buf) & 7]
        self.buf += _Q[LE].pack(v)

    def ulonglong(self, v: int) -> None:
        self.buf += ZEROS[-len(self.buf) & 7]
        self.buf += _QU[LE].pack(v)

    def float(self, v: builtins.float) -> None:
        self.buf += ZEROS[-len(self.buf) & 3]
        self.buf += _F[LE].pack(v)

    def double(self, v: builtins.float) -> None:
        self.buf += ZEROS[-len(self.buf) & 7]
        self.buf += _D[LE].pack(v)

    def string(self, v: str, what: str = "string") -> None:
        put_string(self.buf, v, None, what)

    def octets(self, v: bytes | bytearray | memoryview, what: str = "octets") -> None:
        put_octets(self.buf, v, None, what)

    def length(self, n: int) -> None:
        put_length(self.buf, n, None, "sequence")

    def raw(self, data: bytes | bytearray | memoryview) -> None:
        self.buf += data

    def encapsulation(self, inner: CdrOutput) -> None:
        """`inner` (a stream begun with `encapsulated()`) as an octet sequence."""
        put_octets(self.buf, inner.buf, None, "encapsulation")

    def getvalue(self) -> bytes:
        return bytes(self.buf)


def encapsulated() -> CdrOutput:
    """A stream for an encapsulation: its byte-order octet (little-endian) is written already."""
    return CdrOutput(bytearray(b"\x01"))


class CdrInput:
    """A CDR reader over `data` from `pos` to `end`, in byte order `e` (`LE` or `BE`);
    alignment relative to offset 0 of `data`."""

    __slots__ = ("data", "e", "end", "pos")

    def __init__(
        self, data: bytes | bytearray, pos: int = 0, e: int = LE, end: int | None = None
    ) -> None:
        self.data = data
        self.pos = pos
        self.e = e
        self.end = len(data) if end is None else end

    # ---- primitives -----------------------------------------------------------------------------

    def _take(self, n: int, align: int) -> int:
        p = self.pos + (-self.pos & (align - 1))
        if p + n > self.end:
            raise MARSHAL(f"CDR data ends {p + n - self.end} bytes short")
        self.pos = p + n
        return p

    def align(self, n: int) -> None:
        self.pos = min(self.end, self.pos + (-self.pos & (n - 1)))

    def octet(self) -> int:
        return self.data[self._take(1, 1)]

    def boolean(self) -> bool:
        return self.data[self._take(1, 1)] != 0

    def char(self) -> str:
        return chr(self.data[self._take(1, 1)])

    def int8(self) -> int:
        return int(_B.unpack_from(self.data, self._take(1, 1))[0])

    def short(self) -> int:
        return int(_H[self.e].unpack_from(self.data, self._take(2, 2))[0])

    def ushort(self) -> int:
        return int(_HU[self.e].unpack_from(self.data, self._take(2, 2))[0])

    def long(self) -> int:
        return int(_L[self.e].unpack_from(self.data, self._take(4, 4))[0])

    def ulong(self) -> int:
        return int(_LU[self.e].unpack_from(self.data, self._take(4, 4))[0])

    def longlong(self) -> int:
        return int(_Q[self.e].unpack_from(self.data, self._take(8, 8))[0])

    def ulonglong(self) -> int:
        return int(_QU[self.e].unpack_from(self.data, self._take(8, 8))[0])

    def float(self) -> builtins.float:
        return float(_F[self.e].unpack_from(self.data, self._take(4, 4))[0])

    def double(self) -> builtins.float:
        return float(_D[self.e].unpack_from(self.data, self._take(8, 8))[0])

    def raw(self, n: int) -> bytes:
        if n < 0 or self.pos + n > self.end:
            raise MARSHAL(f"CDR data ends before the {n} bytes expected")
        p = self.pos
        self.pos += n
        return bytes(self.data[p : p + n])

    # ---- strings and sequences ------------------------------------------------------------------

    def string(self, what: str = "string") -> str:
        try:
            value, self.pos = get_string(self._bounded(), self.pos, self.e, None, what)
        except (StructError, IndexError):
            raise MARSHAL(f"{what}: data is truncated") from None
        return value

    def octets(self, what: str = "octets") -> bytes:
        try:
            value, self.pos = get_octets(self._bounded(), self.pos, self.e, None, what)
        except (StructError, IndexError):
            raise MARSHAL(f"{what}: data is truncated") from None
        return value

    def length(self, min_size: int, what: str = "sequence") -> int:
        """A sequence length, checked against the bytes left (`min_size` per element)."""
        try:
            n, self.pos = get_length(self._bounded(), self.pos, self.e, None, min_size, what)
        except (StructError, IndexError):
            raise MARSHAL(f"{what}: data is truncated") from None
        return n

    def encapsulation(self, what: str = "encapsulation") -> CdrInput:
        """The encapsulation that comes next (an octet sequence whose first octet gives its
        byte order), as a stream of its own; this stream moves past it."""
        return encapsulation_input(self.octets(what), what)

    def left(self) -> int:
        return self.end - self.pos

    def _bounded(self) -> bytes | bytearray | memoryview:
        if self.end == len(self.data):
            return self.data
        return memoryview(self.data)[: self.end]


def encapsulation_input(data: bytes, what: str = "encapsulation") -> CdrInput:
    """A stream over an encapsulation's bytes, past its byte-order octet."""
    if not data:
        raise MARSHAL(f"{what}: empty encapsulation")
    if data[0] > 1:
        raise MARSHAL(f"{what}: byte-order octet {data[0]} is neither 0 nor 1")
    return CdrInput(data, 1, LE if data[0] == 1 else BE)
