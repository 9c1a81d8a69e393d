"""Sequences and arrays of numbers as `array.array`, for the codecs `miro-idl` generates.

Sequences and arrays of the integer and floating-point IDL types (`short` ... `unsigned long
long`, `int8`, `uint8`, `float`, `double`) are `array.array`s of type code `h H i I q Q b B f d`
in generated code (DESIGN.md, "Generated Python"): decoding copies the bytes once into a new
array (`frombytes`, byte-swapped only for big-endian data), and `numpy.frombuffer` can view the
result without another copy. Encoding takes an `array.array`, a numpy array, or anything else
with the buffer protocol whose items are numbers of the right kind and size, as bytes, without
looking at the elements; lists, tuples and buffers of another item type are converted element by
element, with the same range checks as every other field.
"""

from __future__ import annotations

import sys
import typing
from array import array
from collections.abc import Sequence
from struct import pack as struct_pack
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias

from miro_gen.exceptions import BAD_PARAM, MARSHAL
from miro_gen.runtime.cdr import (
    LE,
    NATIVE,
    ZEROS,
    Buffer,
    EncodeErrors,
    encode_error,
    get_length,
    put_bulk,
    put_length,
)

if sys.version_info >= (3, 12):
    from collections.abc import Buffer as SupportsBuffer
else:
    from typing_extensions import Buffer as SupportsBuffer

__all__ = [
    "Array",
    "NumberBuffer",
    "get_array",
    "get_sequence",
    "put_array",
    "put_sequence",
    "to_array",
    "to_rows",
    "zeros",
]

# `Array[int]` is what generated code annotates numeric sequences with: `array.array[int]` to a
# type checker, and at run time something Python 3.11 can subscript too (its array.array cannot),
# so that typedef aliases and typing.get_type_hints() evaluate. (typing's own generic alias:
# get_type_hints() subscripts the origin of a types.GenericAlias again.)
if TYPE_CHECKING or sys.version_info >= (3, 12):
    Array = array
else:

    class _ArrayHint:
        """`array.array` in annotations on Python 3.11."""

        def __getitem__(self, item: Any) -> Any:
            return typing._GenericAlias(array, item if isinstance(item, tuple) else (item,))

        def __repr__(self) -> str:
            return "array.array"

    Array = _ArrayHint()


class HasArrayInterface(Protocol):
    """numpy arrays to a type checker that targets Python 3.11, where numpy's stubs do not say
    that they are buffers."""

    @property
    def __array_interface__(self) -> dict[str, Any]: ...


# What generated stubs and servants may send where IDL says numbers, besides any sequence.
NumberBuffer: TypeAlias = SupportsBuffer | HasArrayInterface

# (kind, size) of the buffer item formats numbers come in: signed, unsigned, floating point.
_KIND: dict[str, str] = {
    **dict.fromkeys("bhilqn", "i"),
    **dict.fromkeys("BHILQN", "u"),
    **dict.fromkeys("efd", "f"),
}
# Byte-order prefixes of buffer formats that mean this machine's order (and our wire's, on the
# little-endian machines the fast path is for).
_NATIVE_PREFIXES = "@=<" if sys.byteorder == "little" else "@="


def zeros(code: str, n: int = 0) -> array[Any]:
    """A new array of `n` zeros of type `code` (the default value of a field)."""
    return array(code, [0]) * n


def to_array(code: str, values: Sequence[Any]) -> array[Any]:
    """An array of numbers unpacked with others (a short array in a run of fixed-size fields)."""
    return array(code, values)


def to_rows(code: str, values: Sequence[Any], dims: tuple[int, ...]) -> list[Any]:
    """Row-order `values` as nested lists of shape `dims`, the last dimension as arrays."""
    out: list[Any] = [
        array(code, values[i : i + dims[-1]]) for i in range(0, len(values), dims[-1])
    ]
    for n in reversed(dims[1:-1]):
        out = [out[i : i + n] for i in range(0, len(out), n)]
    return out


def _wire(values: Any, code: str, size: int, what: str) -> tuple[int, Any]:
    """(number of elements, their little-endian bytes) of the numbers in `values`."""
    if type(values) is array and values.typecode == code and NATIVE == LE:
        return len(values), values
    try:
        view = memoryview(values)
    except TypeError:
        view = None  # a list, a tuple, ...
    if view is not None and view.ndim:
        fmt = view.format
        if fmt[:1] in _NATIVE_PREFIXES:
            fmt = fmt[1:]
        if view.itemsize == size and _KIND.get(fmt) == _KIND[code] and NATIVE == LE:
            data = view.cast("B") if view.c_contiguous else view.tobytes()
            return view.nbytes // size, data
        if view.ndim > 1:
            raise BAD_PARAM(f"{what}: a {view.ndim}-dimensional buffer of {view.format!r} items")
    try:
        n = len(values)
        return n, struct_pack(f"<{n}{code}", *values)
    except EncodeErrors as exc:
        raise encode_error(what, exc) from None


def put_sequence(
    buf: bytearray, values: Any, code: str, size: int, bound: int | None, what: str
) -> None:
    """A sequence of numbers of type `code` (`size` bytes each): its length, then the numbers."""
    n, data = _wire(values, code, size, what)
    put_length(buf, n, bound, what)
    if n:
        buf += ZEROS[(4 - len(buf)) & (size - 1)]
        put_bulk(buf, data, n * size)


def put_array(buf: bytearray, values: Any, code: str, size: int, count: int, what: str) -> None:
    """An array of exactly `count` numbers of type `code`."""
    n, data = _wire(values, code, size, what)
    if n != count:
        raise BAD_PARAM(f"{what}: array needs exactly {count} elements, got {n}")
    buf += ZEROS[(4 - len(buf)) & (size - 1)]
    put_bulk(buf, data, n * size)


def _numbers(data: Buffer, off: int, n: int, e: int, code: str, size: int, what: str) -> array[Any]:
    end = off + n * size
    if end > len(data):
        raise MARSHAL(f"{what}: {n} elements cannot fit in the {len(data) - off} bytes left")
    out = array(code)
    out.frombytes(memoryview(data)[off:end])
    if e != NATIVE and size > 1:
        out.byteswap()
    return out


def get_sequence(
    data: Buffer, off: int, e: int, code: str, size: int, bound: int | None, what: str
) -> tuple[array[Any], int]:
    n, off = get_length(data, off, e, bound, size, what)
    if not n:
        return array(code), off
    off += (4 - off) & (size - 1)
    return _numbers(data, off, n, e, code, size, what), off + n * size


def get_array(
    data: Buffer, off: int, e: int, code: str, size: int, count: int, what: str
) -> tuple[array[Any], int]:
    off += (4 - off) & (size - 1)
    return _numbers(data, off, count, e, code, size, what), off + count * size
