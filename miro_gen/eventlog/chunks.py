"""Opening an MCAP chunk without trusting it: sizes capped, CRC checked, records bounded.

A log may be damaged (a flipped bit on a disk, a copy cut short) or made to hurt (a few kB of
zstd that claim gigabytes). Before a byte of a chunk is believed: its header must agree with
its entry in the file's index (when there is one), its decompressed size must be at most
MAX_CHUNK_BYTES and is never exceeded while decompressing, whatever the header says, the
bytes it decompresses to must have its CRC, and every record inside must fit in the chunk.
Anything else is a `LogError` that names the chunk (its number in the file, its offset and
log times), so a damaged log is reported, never printed as wrong values.
"""

from __future__ import annotations

import io
import struct
import zlib
from typing import IO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, McapRecord, Message, Schema

MAX_CHUNK_BYTES = 256 << 20  # decompressed bytes of one chunk (ours are about 1 MiB)
_ZSTD_WINDOW = 1 << 27  # the largest window a zstd frame may ask for (128 MiB)
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length
_CHUNK_HEAD = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed CRC
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


class ChunkError(ValueError):
    """The chunk cannot be believed; the message says why (the caller names the chunk)."""


def read_chunk(file: IO[bytes], offset: int, file_size: int) -> Chunk:
    """The chunk record at `offset` of `file` (its opcode and length checked first)."""
    file.seek(offset)
    head = file.read(_RECORD_HEAD.size)
    if len(head) != _RECORD_HEAD.size:
        raise ChunkError("cut off")
    opcode, length = _RECORD_HEAD.unpack(head)
    if opcode != Opcode.CHUNK:
        raise ChunkError(f"no chunk there (record opcode {opcode:#x})")
    if length > file_size - offset - _RECORD_HEAD.size:
        raise ChunkError(f"its length ({length} bytes) runs past the end of the file")
    body = file.read(length)
    return parse_chunk(body)


def parse_chunk(body: bytes) -> Chunk:
    """A chunk record's fields, from its body (what follows opcode and length)."""
    try:
        start, end, size, crc = _CHUNK_HEAD.unpack_from(body)
        at = _CHUNK_HEAD.size
        (n,) = struct.unpack_from("<I", body, at)
        compression = body[at + 4 : at + 4 + n].decode("utf-8")
        at += 4 + n
        (data_length,) = struct.unpack_from("<Q", body, at)
        at += 8
    except (struct.error, UnicodeDecodeError) as e:
        raise ChunkError(f"its header does not parse ({e})") from None
    if at + data_length > len(body):
        raise ChunkError("its compressed data runs past its record")
    return Chunk(
        compression=compression,
        data=body[at : at + data_length],
        message_end_time=end,
        message_start_time=start,
        uncompressed_crc=crc,
        uncompressed_size=size,
    )


def check_against_index(chunk: Chunk, index: ChunkIndex) -> None:
    """The chunk's header must say what the file's index (CRC-checked) says of it."""
    for field, index_field in (
        ("compression", "compression"),
        ("uncompressed_size", "uncompressed_size"),
        ("message_start_time", "message_start_time"),
        ("message_end_time", "message_end_time"),
    ):
        if getattr(chunk, field) != getattr(index, index_field):
            raise ChunkError(f"its header's {field} is not what the file's index says")
    if len(chunk.data) != index.compressed_size:
        raise ChunkError("its compressed size is not what the file's index says")


def chunk_records(
    chunk: Chunk, max_bytes: int = MAX_CHUNK_BYTES, messages_only: bool = False
) -> list[McapRecord]:
    """The schema, channel and message records of a chunk (only the messages when the file's
    summary holds the rest), after checking it."""
    if chunk.uncompressed_size > max_bytes:
        raise ChunkError(
            f"it says it holds {chunk.uncompressed_size} bytes, more than the "
            f"{max_bytes} a chunk may hold"
        )
    data = _decompress(chunk, chunk.uncompressed_size)
    if len(data) > chunk.uncompressed_size:
        raise ChunkError(
            f"it decompresses to more than the {chunk.uncompressed_size} bytes its header says"
        )
    if len(data) < chunk.uncompressed_size:
        raise ChunkError(
            f"it decompresses to {len(data)} bytes, not the {chunk.uncompressed_size} its "
            "header says"
        )
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ChunkError("its CRC does not match its data: the data is damaged")
    return _records(data, messages_only)


def _decompress(chunk: Chunk, expected: int) -> bytes:
    """At most `expected` + 1 bytes of the chunk's data, decompressed."""
    limit = expected + 1
    try:
        if chunk.compression == "":
            return chunk.data[:limit]
        if chunk.compression == "zstd":
            import zstandard

            dctx = zstandard.ZstdDecompressor(max_window_size=_ZSTD_WINDOW)
            out = bytearray()
            with dctx.stream_reader(io.BytesIO(chunk.data)) as reader:
                while len(out) < limit:
                    piece = reader.read(min(1 << 20, limit - len(out)))
                    if not piece:
                        break
                    out += piece
            return bytes(out)
        if chunk.compression == "lz4":
            import lz4.frame  # type: ignore[import-untyped]

            return bytes(lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, limit))
    except Exception as e:  # zstandard.ZstdError, RuntimeError of lz4: not valid data
        raise ChunkError(f"its {chunk.compression} data does not decompress ({e})") from None
    raise ChunkError(f"its compression {chunk.compression!r} is not one MCAP knows")


def _records(data: bytes, messages_only: bool) -> list[McapRecord]:
    out: list[McapRecord] = []
    at, end = 0, len(data)
    head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
    while at < end:
        if end - at < _RECORD_HEAD.size:
            raise ChunkError("a record is cut off at its end")
        opcode, length = head(data, at)
        at += _RECORD_HEAD.size
        if length > end - at:
            raise ChunkError("a record runs past the chunk's end")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise ChunkError("a message record is too short")
            channel, sequence, log_time, publish_time = message_head(data, at)
            start = at + _MESSAGE_HEAD.size
            at += length
            out.append(Message(channel, log_time, data[start:at], publish_time, sequence))
            continue
        body = data[at : at + length]
        at += length
        if messages_only:
            continue
        stream = ReadDataStream(io.BytesIO(body))
        try:
            if opcode == Opcode.CHANNEL:
                out.append(Channel.read(stream))
            elif opcode == Opcode.SCHEMA:
                out.append(Schema.read(stream))
        except ChunkError:
            raise
        except Exception as e:  # a length inside the record that lies, bad UTF-8
            raise ChunkError(f"a record does not parse ({type(e).__name__}: {e})") from None
        if opcode in (Opcode.CHANNEL, Opcode.SCHEMA) and stream.count != length:
            raise ChunkError("a record's fields do not fill it")
    return out
