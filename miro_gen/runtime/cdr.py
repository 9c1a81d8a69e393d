"""Support for the CDR codecs that `miro-idl` generates (OMG CDR, XCDR1, as Cyclone DDS writes it).

Generated code does the fixed-layout work itself with precompiled `struct.Struct`s; this module
holds what is shared: the encapsulation header, strings, sequences, unions, object references,
and the checks that make decoding of malformed input fail at once with `MARSHAL` (every length
is compared with the bytes that remain before anything is allocated). Sequences and arrays of
numbers, which are `array.array`s, are in `arrays.py`; the base classes of generated types in
`datatypes.py`, and which class has a type hash in `registry.py`.

Offsets count from the start of the buffer, which begins with the 4-byte encapsulation header;
alignment is relative to the end of that header, so the padding before a value of alignment `a`
at offset `o` is `(4 - o) & (a - 1)`.
"""

from __future__ import annotations

import sys
import threading
from array import array
from collections.abc import Callable, Sequence
from itertools import chain
from struct import Struct
from struct import error as StructError
from struct import pack as struct_pack
from struct import unpack as struct_unpack
from struct import unpack_from as struct_unpack_from
from typing import Any, Final, NamedTuple

from miro_gen.exceptions import BAD_PARAM, MARSHAL, CompletionStatus
from miro_gen.runtime import registry
from miro_gen.runtime.datatypes import IdlType as IdlType  # generated code's bases, as before
from miro_gen.runtime.datatypes import IdlUnion as IdlUnion
from miro_gen.runtime.datatypes import default_discriminator as default_discriminator
from miro_gen.runtime.views import active as _views

# Which generated class has a type hash or a repository id: miro_gen.runtime.registry (these
# names stay importable from here).
type_for_hash = registry.find
type_for_repo_id = registry.find_repo_id
imported_types = registry.known_types

HEADER_LE: Final = b"\x00\x01\x00\x00"  # CDR_LE encapsulation, what we write
LE: Final = 0  # endianness index into the (little, big) Struct pairs of generated code
BE: Final = 1
NATIVE: Final = LE if sys.byteorder == "little" else BE
ZEROS: Final = tuple(b"\0" * n for n in range(8))

# What generated codecs turn into MARSHAL (decoding) or BAD_PARAM (encoding). RecursionError:
# recursive types are decoded recursively, so data nested thousands deep runs out of stack.
DecodeErrors: Final = (
    StructError,
    IndexError,
    ValueError,
    OverflowError,
    UnicodeDecodeError,
    RecursionError,
)
EncodeErrors: Final = (
    StructError,
    TypeError,
    ValueError,
    OverflowError,
    AttributeError,
    KeyError,
    RecursionError,
)

_U32: Final = (Struct("<I"), Struct(">I"))
_U32_LE: Final = _U32[LE]
_U32_UNPACK: Final = (_U32[LE].unpack_from, _U32[BE].unpack_from)
# Elements that may take no bytes at all (empty structs) cannot be checked against the bytes
# left: one decode may create this many of them in all (sequences of them nested in sequences
# would otherwise multiply a lying length). Each thread's budget is refilled by
# body_header(), which every decode of a whole value starts with.
_EMPTY_ELEMENTS: Final = 1 << 16
_zero_size = threading.local()
_XCDR2_KINDS: Final = {6, 7, 8, 9, 10, 11}
# struct format letters whose array type code differs ("i" is a C int in both on every platform
# this runs on; "?" has no array type: booleans travel as bytes).
_ARRAY_CODES: Final = {"?": "B"}


class Encoder(bytearray):
    """What generated encoders append to: a bytearray that starts with the encapsulation header
    (alignment counts from its length), and keeps large payloads (sequences of numbers or
    octets, `put_bulk`) aside rather than copy them in, so that `value()` copies each byte of
    the encoded value once."""

    parts: list[Any] | None = None  # what came before the last payload set aside, and payloads
    skip = 0  # bytes at the start that only keep the alignment of what follows a payload

    def set_aside(self, data: Any, nbytes: int) -> None:
        """Append `data` (`nbytes` bytes, any buffer) without copying it yet."""
        if self.parts is None:
            self.parts = []
        self.parts += (self[self.skip :], data)
        # Only the length modulo 8 matters to what follows: keep that many placeholder bytes.
        self.skip = (len(self) + nbytes) & 7
        self[:] = ZEROS[self.skip]

    def value(self) -> bytes:
        """The encoded value."""
        if self.parts is None:
            return bytes(self)
        return b"".join((*self.parts, memoryview(self)[self.skip :]))

    @property
    def size(self) -> int:
        """Bytes encoded so far."""
        kept = sum(memoryview(p).nbytes for p in self.parts) if self.parts is not None else 0
        return kept + len(self) - self.skip

    def copy_into(self, out: memoryview) -> int:
        """Write the encoded value into `out` (at least `size` bytes, a shared-memory slot):
        each byte copied once, as by `value()`; how many were written."""
        at = 0
        for part in (*(self.parts or ()), memoryview(self)[self.skip :]):
            m = memoryview(part).cast("B")
            out[at : at + m.nbytes] = m
            at += m.nbytes
        return at

    def overwrite(self, at: int, data: bytes) -> None:
        """Replace bytes at offset `at`, before the first payload set aside (a header's)."""
        first = self if self.parts is None else self.parts[0]
        first[at : at + len(data)] = data


def encode_after(head: bytes, value: IdlType) -> Encoder:
    """`value` encoded after `head` and the encapsulation header: a frame put together in one
    copy. `head` must be a multiple of 8 bytes long, so that the CDR is aligned as usual."""
    if len(head) & 7:
        raise ValueError(f"a head of {len(head)} bytes would misalign the CDR after it")
    buf = Encoder(head + HEADER_LE)
    value._encode(buf)
    return buf


# Payloads from this size on are set aside by an Encoder; smaller ones are cheaper to copy in.
LARGE: Final = 1 << 16


def put_bulk(buf: bytearray, data: Any, nbytes: int) -> None:
    """Append `data` (`nbytes` bytes, any buffer): set aside when large, else copied in."""
    if nbytes >= LARGE and type(buf) is Encoder:
        buf.set_aside(data, nbytes)
    else:
        buf += data


def pair(fmt: str) -> tuple[Struct, Struct]:
    """Little- and big-endian `Struct`s for `fmt` (no byte-order prefix)."""
    return Struct("<" + fmt), Struct(">" + fmt)


def body_header(data: bytes | bytearray | memoryview) -> tuple[int, int]:
    """Check the encapsulation header (generated decoders start with it): the endianness index
    of the values that follow, and the offset where they begin. That is 4, after the header,
    or further on in a body that came in a GIOP 1.0/1.1 message: after the zero bytes that keep
    the alignment its values had there (`ForeignBody.start`)."""
    _zero_size.left = _EMPTY_ELEMENTS
    if len(data) < 4:
        raise MARSHAL(f"{len(data)} bytes is too short for a CDR encapsulation header")
    kind = data[1]
    if data[0] != 0 or kind not in (0, 1):
        if data[0] == 0 and kind in _XCDR2_KINDS:
            raise MARSHAL(f"XCDR2 encapsulation (kind {kind}) is not supported; expected XCDR1")
        raise MARSHAL(f"unknown CDR encapsulation kind {data[0]:02x} {kind:02x}")
    return (LE if kind == 1 else BE), (data.start if isinstance(data, ForeignBody) else 4)


def header_endianness(data: bytes | bytearray | memoryview) -> int:
    """Check the encapsulation header; the endianness index of the data that follows."""
    return body_header(data)[0]


def body_start(data: bytes | bytearray | memoryview) -> int:
    """Where the values of a body begin (see `body_header`)."""
    return data.start if isinstance(data, ForeignBody) else 4


# ---- strings ----------------------------------------------------------------------------------


def put_string(buf: bytearray, value: str, bound: int | None, what: str) -> None:
    """A string: aligned ulong length (bytes + NUL), UTF-8 bytes, NUL."""
    if not isinstance(value, str):
        raise BAD_PARAM(f"{what}: expected str, got {type(value).__name__}")
    raw = value.encode("utf-8")
    if bound is not None and len(raw) > bound:
        raise BAD_PARAM(f"{what}: {len(raw)} bytes is longer than the bound {bound}")
    if b"\0" in raw:
        raise BAD_PARAM(f"{what}: strings cannot contain NUL characters")
    buf += ZEROS[-len(buf) & 3]
    buf += _U32_LE.pack(len(raw) + 1)
    buf += raw
    buf.append(0)


def get_string(
    data: bytes | bytearray | memoryview, off: int, e: int, bound: int | None, what: str
) -> tuple[str, int]:
    off += -off & 3
    (n,) = _U32[e].unpack_from(data, off)
    off += 4
    if n == 0:  # some writers encode "" without its NUL
        return "", off
    if n > len(data) - off:
        raise MARSHAL(f"{what}: string length {n} exceeds the {len(data) - off} bytes left")
    end = off + n
    if data[end - 1] != 0:
        raise MARSHAL(f"{what}: string is not NUL-terminated")
    if bound is not None and n - 1 > bound:
        raise MARSHAL(f"{what}: string of {n - 1} bytes exceeds its bound {bound}")
    try:
        text = str(data[off : end - 1], "utf-8")
    except UnicodeDecodeError:
        raise MARSHAL(f"{what}: string is not valid UTF-8") from None
    if "\0" in text:
        raise MARSHAL(f"{what}: string holds a NUL before its end")
    return text, end


def put_wstring(buf: bytearray, value: str, bound: int | None, what: str) -> None:
    """A wide string as the ROS 2 RMWs write it (rosidl_typesupport_fastrtps, rmw_cyclonedds):
    an aligned ulong count of UTF-16 code units, then each unit as a ulong; no NUL. A bound
    counts code units."""
    if not isinstance(value, str):
        raise BAD_PARAM(f"{what}: expected str, got {type(value).__name__}")
    try:
        raw = value.encode("utf-16-le")
    except UnicodeEncodeError:
        raise BAD_PARAM(f"{what}: wide strings cannot hold lone surrogates") from None
    n = len(raw) // 2
    if bound is not None and n > bound:
        raise BAD_PARAM(f"{what}: {n} UTF-16 units is longer than the bound {bound}")
    if "\0" in value:
        raise BAD_PARAM(f"{what}: wide strings cannot contain NUL characters")
    buf += ZEROS[-len(buf) & 3]
    buf += _U32_LE.pack(n)
    buf += struct_pack(f"<{n}I", *struct_unpack(f"<{n}H", raw))


def get_wstring(
    data: bytes | bytearray | memoryview, off: int, e: int, bound: int | None, what: str
) -> tuple[str, int]:
    off += -off & 3
    (n,) = _U32[e].unpack_from(data, off)
    off += 4
    if n > (len(data) - off) // 4:
        raise MARSHAL(f"{what}: wide string of {n} units exceeds the {len(data) - off} bytes left")
    if bound is not None and n > bound:
        raise MARSHAL(f"{what}: wide string of {n} units exceeds its bound {bound}")
    units = struct_unpack_from(("<" if e == LE else ">") + f"{n}I", data, off)
    if any(u > 0xFFFF for u in units):
        raise MARSHAL(f"{what}: a wide character above 0xFFFF is not a UTF-16 unit")
    try:
        text = struct_pack(f"<{n}H", *units).decode("utf-16-le")
    except UnicodeDecodeError:
        raise MARSHAL(f"{what}: wide string is not valid UTF-16") from None
    return text, off + 4 * n


# ---- sequences ---------------------------------------------------------------------------------


def put_length(buf: bytearray, n: int, bound: int | None, what: str) -> None:
    """The ulong length of a sequence, checked against its bound."""
    if bound is not None and n > bound:
        raise BAD_PARAM(f"{what}: {n} elements is more than the bound {bound}")
    buf += ZEROS[-len(buf) & 3]
    buf += _U32_LE.pack(n)


def get_length(
    data: bytes | bytearray | memoryview,
    off: int,
    e: int,
    bound: int | None,
    min_size: int,
    what: str,
) -> tuple[int, int]:
    """A sequence length, checked against its bound and against the bytes left
    (`min_size`: the fewest bytes one element can take), before anything is allocated."""
    off += -off & 3
    n = _U32_UNPACK[e](data, off)[0]
    off += 4
    if bound is not None and n > bound:
        raise MARSHAL(f"{what}: {n} elements exceeds the bound {bound}")
    if n and min_size and n * min_size > len(data) - off:
        raise MARSHAL(f"{what}: {n} elements cannot fit in the {len(data) - off} bytes left")
    if n and not min_size:
        left = getattr(_zero_size, "left", _EMPTY_ELEMENTS)
        if n > left:
            raise MARSHAL(
                f"{what}: {n} empty elements is more than the {_EMPTY_ELEMENTS} one value may hold"
            )
        _zero_size.left = left - n
    return n, off


def count(values: Sequence[Any], what: str) -> int:
    """len(values), or BAD_PARAM naming the field when the value is no sequence at all."""
    try:
        return len(values)
    except TypeError:
        raise BAD_PARAM(f"{what}: expected a sequence, got {type(values).__name__}") from None


def put_count(buf: bytearray, values: Sequence[Any], bound: int | None, what: str) -> None:
    """The length of a sequence whose elements are encoded one by one after it."""
    put_length(buf, count(values, what), bound, what)


def put_octets(
    buf: bytearray, value: bytes | bytearray | memoryview, bound: int | None, what: str
) -> None:
    """Octets: `bytes`, or any other buffer (a bytearray, a memoryview, a numpy image), as
    the bytes it holds in row order."""
    data: Any = value
    if not isinstance(value, bytes):
        try:
            view = memoryview(value)
        except TypeError:
            raise BAD_PARAM(f"{what}: expected bytes, got {type(value).__name__}") from None
        data = view.cast("B") if view.c_contiguous else view.tobytes()
    put_length(buf, len(data), bound, what)
    put_bulk(buf, data, len(data))


def get_octets(
    data: bytes | bytearray | memoryview, off: int, e: int, bound: int | None, what: str
) -> tuple[bytes, int]:
    n, off = get_length(data, off, e, bound, 1, what)
    if type(data) is memoryview and data.readonly and getattr(_views, "on", False):
        view: Any = data[off : off + n]  # stands in for bytes (runtime.views)
        return view, off + n
    return bytes(data[off : off + n]), off + n


def put_enums(
    buf: bytearray, values: Sequence[Any], wire: dict[int, int], bound: int | None, what: str
) -> None:
    """A sequence of enumerators; `wire` maps each valid ordinal to itself (KeyError if not)."""
    try:
        ordinals = [wire[v] for v in values]
    except (KeyError, TypeError) as exc:
        raise encode_error(what, exc) from None
    put_length(buf, len(ordinals), bound, what)
    if ordinals:
        buf += struct_pack(f"<{len(ordinals)}I", *ordinals)


def get_enums(
    data: bytes | bytearray | memoryview,
    off: int,
    e: int,
    table: tuple[Any, ...],
    bound: int | None,
    what: str,
) -> tuple[list[Any], int]:
    """A sequence of enumerators (`table`: the enum's members by ordinal)."""
    n, off = get_length(data, off, e, bound, 4, what)  # checks that the n ulongs are there
    end = off + 4 * n
    return enums(table, _values(data, off, end, e, "I"), what), end


def _values(
    data: bytes | bytearray | memoryview, off: int, end: int, e: int, code: str
) -> list[Any]:
    """The primitives in data[off:end]: a view cast to the type in native order (fastest),
    or through a byte-swapped array for the other byte order."""
    if e == NATIVE:
        view: Any = memoryview(data)[off:end]
        values: list[Any] = view.cast(code).tolist()
        return values
    raw = array(_ARRAY_CODES.get(code, code))
    raw.frombytes(data[off:end])
    raw.byteswap()
    return raw.tolist()


def put_booleans(buf: bytearray, values: Sequence[bool], bound: int | None, what: str) -> None:
    put_length(buf, count(values, what), bound, what)
    buf += bytes(map(bool, values))


def get_booleans(
    data: bytes | bytearray | memoryview, off: int, e: int, bound: int | None, what: str
) -> tuple[list[bool], int]:
    n, off = get_length(data, off, e, bound, 1, what)
    return [b != 0 for b in data[off : off + n]], off + n


def put_chars(buf: bytearray, values: Sequence[str], bound: int | None, what: str) -> None:
    put_length(buf, count(values, what), bound, what)
    try:
        buf += bytes(map(ord, values))  # ord: exactly one character; bytes: Latin-1 only
    except TypeError:
        raise BAD_PARAM(f"{what}: each element must be one character") from None
    except ValueError:
        raise BAD_PARAM(f"{what}: characters must be ISO Latin-1") from None


def get_chars(
    data: bytes | bytearray | memoryview, off: int, e: int, bound: int | None, what: str
) -> tuple[list[str], int]:
    n, off = get_length(data, off, e, bound, 1, what)
    return list(str(data[off : off + n], "latin-1")), off + n


def check_no_branch(value: Any, discriminator: Any, what: str) -> None:
    """A union whose discriminator selects no branch holds no value (only the discriminator is
    sent); one given anyway would be lost, so it is refused."""
    if value is not None:
        raise BAD_PARAM(
            f"{what}: discriminator {discriminator!r} selects no branch, but a value is set"
        )


def check_length(values: Sequence[Any], n: int, what: str) -> None:
    """Arrays have a fixed length."""
    if count(values, what) != n:
        raise BAD_PARAM(f"{what}: array needs exactly {n} elements, got {len(values)}")


def enum_value(table: tuple[Any, ...], value: int, what: str) -> Any:
    """The enumerator with ordinal `value` (enums are ulongs on the wire); unknown: MARSHAL."""
    if value < len(table):
        return table[value]
    raise MARSHAL(f"{what}: {value} is not a valid enumerator ordinal (0 to {len(table) - 1})")


# ---- object references -------------------------------------------------------------------------


class ObjectRef(NamedTuple):
    """A reference to a remote object: its repository id, the endpoint that serves it, and its
    key there. Travels as two strings and an octet sequence; the nil reference is all empty."""

    repo_id: str = ""
    endpoint: str = ""
    key: bytes = b""

    def __bool__(self) -> bool:
        return bool(self.endpoint or self.key)


class EncodedRef(NamedTuple):
    """An object reference already encoded for the protocol its message goes over (an IOR in
    CDR, for a GIOP peer): what `miro_gen.runtime.rpc.to_ref` returns for an invoker that
    encodes references its own way. `data` is written as it is, at a 4-aligned offset."""

    data: bytes


class ForeignBody(bytes):
    """A request or reply body that came over a protocol whose object references are not
    (repository id, endpoint, key) triples: `get_object` decodes them (GIOP bodies hold IORs).

    `start` is where its values begin (`body_start`). Values are aligned relative to the end of
    the 4-byte header; a GIOP 1.0/1.1 body may begin anywhere in its message, whose start its
    values are aligned to, so zero bytes after the header put them at the same place modulo 8."""

    start: int = 4  # set on an instance that has padding

    def get_object(self, off: int, e: int, what: str) -> tuple[ObjectRef, int]:
        raise NotImplementedError  # pragma: no cover - subclasses implement it


def put_object(buf: bytearray, ref: Any, what: str) -> None:
    """An object reference: an `ObjectRef`, a stub (its `_ref`), an `EncodedRef`, or None."""
    if ref is None:
        ref = ObjectRef()
    elif isinstance(ref, EncodedRef):
        buf += ZEROS[-len(buf) & 3]
        buf += ref.data
        return
    elif not isinstance(ref, ObjectRef):
        ref = getattr(ref, "_ref", None)
        if not isinstance(ref, ObjectRef):
            raise BAD_PARAM(f"{what}: expected an object reference or a stub")
    put_string(buf, ref.repo_id, None, what)
    put_string(buf, ref.endpoint, None, what)
    put_octets(buf, ref.key, None, what)


def get_object(
    data: bytes | bytearray | memoryview, off: int, e: int, what: str
) -> tuple[ObjectRef, int]:
    if isinstance(data, ForeignBody):
        return data.get_object(off, e, what)
    repo_id, off = get_string(data, off, e, None, what)
    endpoint, off = get_string(data, off, e, None, what)
    key, off = get_octets(data, off, e, None, what)
    return ObjectRef(repo_id, endpoint, key), off


def marshal_error(what: str, exc: BaseException) -> MARSHAL:
    """The MARSHAL error for data that ran out or did not decode (from generated decoders)."""
    if isinstance(exc, MARSHAL):
        return exc
    if isinstance(exc, StructError | IndexError):
        return MARSHAL(f"{what}: data is truncated")
    if isinstance(exc, RecursionError):
        return MARSHAL(f"{what}: data is nested too deeply to decode")
    return MARSHAL(f"{what}: {exc}")


def encode_error(what: str, exc: BaseException) -> BAD_PARAM:
    """The BAD_PARAM error for a value that does not fit its IDL type (from generated encoders)."""
    if isinstance(exc, BAD_PARAM):
        return exc
    if isinstance(exc, RecursionError):
        return BAD_PARAM(f"{what}: value is nested too deeply to encode")
    if isinstance(exc, KeyError):  # only the enum ordinal checks (`_E_W[v]`) raise it
        return BAD_PARAM(f"{what}: {exc.args[0]!r} is not one of its enumerators")
    return BAD_PARAM(f"{what}: {exc}")


ResultErrors: Final = (*EncodeErrors, BAD_PARAM)
NestedErrors: Final = ResultErrors
_LONGEST_PATH: Final = 400  # characters of field path an error message keeps


def pack_error(
    exc: BaseException, *items: tuple[str, str, Callable[[], tuple[Any, ...]]]
) -> BAD_PARAM:
    """BAD_PARAM naming the value that did not fit, of several packed together (from generated
    encoders, once packing has failed): each item is (what, struct format, its wire values)."""
    for what, fmt, values in items:
        try:
            wire = values()
            n = int(fmt[:-1] or 1)
            if len(wire) != n:
                return BAD_PARAM(f"{what}: array needs exactly {n} elements, got {len(wire)}")
            struct_pack("<" + fmt, *wire)
        except BAD_PARAM as named:
            return named
        except EncodeErrors as problem:
            return encode_error(what, problem)
    return encode_error(items[0][0] if items else "value", exc)


def nested_error(what: str, exc: BaseException) -> BAD_PARAM:
    """BAD_PARAM for a struct, union or exception value inside another: the message leads with
    the field that holds it, so it reads as a path (`Line.a: Point.x: ...`)."""
    inner = encode_error(what, exc)
    if not isinstance(exc, BAD_PARAM) or len(inner.message) > _LONGEST_PATH:
        return inner
    return BAD_PARAM(f"{what}: {inner.message}", inner.minor, inner.completed)


def result_error(what: str, exc: BaseException) -> MARSHAL:
    """The error for results a servant returned that do not fit their IDL types (from generated
    skeletons): MARSHAL, completed YES, since the operation has run; a client must not take it
    for a call that can safely be repeated."""
    problem = encode_error(what, exc).message
    done = CompletionStatus.YES
    return MARSHAL(f"{problem} (in the results the servant returned)", completed=done)


# ---- bulk helpers for generated code ---------------------------------------------------------

Buffer = bytes | bytearray | memoryview


def put_flat(
    buf: bytearray,
    values: Sequence[Any],
    getter: Callable[[Any], Any],
    members: int,
    code: str,
    size: int,
    bound: int | None,
    what: str,
) -> None:
    """A sequence of structs whose `members` members all have one primitive type, in bulk."""
    n = count(values, what)
    put_length(buf, n, bound, what)
    if n:
        try:
            flat = map(getter, values) if members == 1 else chain.from_iterable(map(getter, values))
            packed = struct_pack(f"<{n * members}{code}", *flat)
        except EncodeErrors as exc:
            raise encode_error(what, exc) from None
        buf += ZEROS[(4 - len(buf)) & (size - 1)]
        put_bulk(buf, packed, len(packed))


def get_flat(
    data: Buffer,
    off: int,
    e: int,
    cls: Callable[..., Any],
    count: int,
    code: str,
    size: int,
    bound: int | None,
    what: str,
) -> tuple[list[Any], int]:
    n, off = get_length(data, off, e, bound, size * count, what)
    if not n:
        return [], off
    off += (4 - off) & (size - 1)
    end = off + n * count * size
    if end > len(data):
        raise MARSHAL(f"{what}: {n} elements cannot fit in the {len(data) - off} bytes left")
    it = iter(_values(data, off, end, e, code))
    return list(map(cls, *([it] * count))), end


def flatten(
    value: Sequence[Any], dims: tuple[int, ...], what: str, convert: Any = None
) -> list[Any]:
    """The elements of a (multi-dimensional) array in row order, checking every length."""
    rows: list[Any] = [value]
    for n in dims:
        nxt: list[Any] = []
        for row in rows:
            check_length(row, n, what)
            nxt.extend(row)
        rows = nxt
    return list(map(convert, rows)) if convert is not None else rows


def reshape(values: Sequence[Any], dims: tuple[int, ...]) -> list[Any]:
    """Row-order `values` as nested lists of shape `dims`."""
    out: list[Any] = list(values)
    for n in reversed(dims[1:]):
        out = [out[i : i + n] for i in range(0, len(out), n)]
    return out


def enums(table: tuple[Any, ...], values: Sequence[int], what: str) -> list[Any]:
    """Enumerators for wire values; MARSHAL for a value that names none."""
    try:
        return [table[v] for v in values]
    except IndexError:
        bad = next(v for v in values if v >= len(table))
        raise MARSHAL(f"{what}: {bad} is not a valid enumerator ordinal") from None


def exception_text(exc: Any) -> str:
    """`str()` of a generated user exception: its IDL name and fields."""
    import dataclasses

    fields = ", ".join(f"{f.name}={getattr(exc, f.name)!r}" for f in dataclasses.fields(exc))
    return f"{exc._type_name}({fields})"
