"""Checking a finished log's summary against its chunks, cheaply or thoroughly.

`miro log info` reads a finished file through its summary alone: its counts, times and topics.
A file whose chunks were damaged after it was written (a flipped bit, a copy cut short, a file
pieced together) still has a summary that looks right. So every time, `disagreements` reads
each chunk's header where the index says it is (37 bytes per chunk, one `pread` each: a
buffered file would read 8 KiB for each, which costs more than the summary itself) and, in a
file of at most QUICK_CRC_BYTES whose writer stored it (ours do), the data section's CRC
(bytes read, nothing decompressed). With `--check`, `damage` also opens every chunk:
decompressed, CRC-checked, parsed, its events counted against the statistics; and reads the
data section through once for chunks the index does not name. Each finding is one line, in
the words of `reader.LogError` (a chunk by its number, offset and log times).
"""

from __future__ import annotations

import os
import struct
import zlib
from collections import Counter
from typing import IO

from mcap.opcode import Opcode
from mcap.records import Chunk, ChunkIndex, DataEnd, Message
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

from miro_gen.eventlog.chunks import ChunkError, check_against_index, chunk_records, read_chunk
from miro_gen.eventlog.reader import MAGIC, chunk_fault

QUICK_CRC_BYTES = 256 << 20  # larger files: the data CRC only with --check (reading costs)
_HEADER = struct.Struct("<BQQQQI")  # opcode, length; start, end, uncompressed size and CRC
_FOOTER = 29  # opcode, length, summary start, summary offset start, CRC
_DATA_END = struct.Struct("<BQI")  # opcode, length, the data section's CRC


def disagreements(path: str, summary: Summary) -> list[str]:
    """Where the summary and the chunks' own headers disagree (a read of 37 bytes per chunk):
    a chunk past the data section's end, not a chunk where the index says, or whose header
    says other sizes or times; statistics that do not add up."""
    found: list[str] = []
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        end = _data_end(f, size)
        for number, index in enumerate(summary.chunk_indexes, 1):
            why = _header_disagrees(f.fileno(), index, end)
            if why is not None:
                found.append(_chunk(number, index, why))
        if end <= QUICK_CRC_BYTES:
            found += _data_crc(f, end)
    stats = summary.statistics
    if stats is not None:
        if stats.chunk_count != len(summary.chunk_indexes):
            found.append(
                f"the statistics count {stats.chunk_count} chunks, the index "
                f"{len(summary.chunk_indexes)}"
            )
        if stats.message_count != sum(stats.channel_message_counts.values()):
            found.append(
                f"the statistics count {stats.message_count} events, their topics "
                f"{sum(stats.channel_message_counts.values())}"
            )
        unknown = sorted(set(stats.channel_message_counts) - set(summary.channels))
        if unknown:
            found.append(f"the statistics count events of unknown channels {unknown}")
    return found


def damage(path: str, summary: Summary) -> tuple[list[str], int, int]:
    """Every chunk read and checked: (the findings, chunks read, events in them)."""
    found: list[str] = []
    counts: Counter[int] = Counter()
    chunks = 0
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        end = _data_end(f, size)
        for number, index in enumerate(summary.chunk_indexes, 1):
            why = _header_disagrees(f.fileno(), index, end)
            if why is not None:
                found.append(_chunk(number, index, why))
                continue
            try:
                chunk = read_chunk(f, index.chunk_start_offset, size)
                check_against_index(chunk, index)
                records = chunk_records(chunk)
            except ChunkError as e:
                found.append(chunk_fault(number, index.chunk_start_offset, index, e))
                continue
            chunks += 1
            for r in records:
                if not isinstance(r, Message):
                    continue
                if r.channel_id not in summary.channels:
                    found.append(
                        _chunk(number, index, f"an event of unknown channel {r.channel_id}")
                    )
                    break
                if not index.message_start_time <= r.log_time <= index.message_end_time:
                    found.append(_chunk(number, index, "an event outside its time span"))
                    break
                counts[r.channel_id] += 1
        found += _data_crc(f, end)
        found += _unindexed(f, size, summary)
    stats = summary.statistics
    if stats is not None and not found:  # a damaged chunk's events cannot be counted
        for cid in sorted(set(stats.channel_message_counts) | set(counts)):
            said, held = stats.channel_message_counts.get(cid, 0), counts.get(cid, 0)
            if said != held:
                channel = summary.channels.get(cid)
                topic = channel.topic if channel is not None else f"channel {cid}"
                found.append(
                    f"the statistics count {said} events of {topic}, its chunks hold {held}"
                )
    return found, chunks, sum(counts.values())


def _data_end(f: IO[bytes], size: int) -> int:
    """Where the data section ends (the summary starts), from the footer; else the footer."""
    footer = size - len(MAGIC) - _FOOTER
    f.seek(footer + 9)
    raw = f.read(8)
    start = struct.unpack("<Q", raw)[0] if len(raw) == 8 else 0
    return start if len(MAGIC) <= start <= footer else footer


def _data_crc(f: IO[bytes], end: int) -> list[str]:
    """The data section's CRC, when its writer stored one (in the DataEnd record before `end`)."""
    at = end - _DATA_END.size
    if at < len(MAGIC):
        return []
    f.seek(at)
    raw = f.read(_DATA_END.size)
    if len(raw) != _DATA_END.size:
        return []
    opcode, length, crc = _DATA_END.unpack(raw)
    if opcode != Opcode.DATA_END or length != 4 or crc == 0:
        return []  # another layout (padding, more fields), or no CRC stored
    f.seek(0)
    value, left = 0, at
    while left > 0:
        piece = f.read(min(left, 1 << 20))
        if not piece:
            break
        value = zlib.crc32(piece, value)
        left -= len(piece)
    if value == crc:
        return []
    return ["the data section's CRC does not match its bytes: some were changed after writing"]


def _header_disagrees(fd: int, index: ChunkIndex, end: int) -> str | None:
    """Why the chunk header at the index's offset in the file `fd` is not what the index
    says, or None. `pread`: no seek, and only the header's bytes read."""
    offset, length = index.chunk_start_offset, index.chunk_length
    if offset < len(MAGIC) or offset + length > end:
        return (
            f"the index puts it at bytes {offset} to {offset + length}, past the data's end ({end})"
        )
    raw = os.pread(fd, _HEADER.size, offset)
    if len(raw) < _HEADER.size:
        return "cut off"
    opcode, body, start, stop, usize, _ = _HEADER.unpack(raw)
    if opcode != Opcode.CHUNK:
        return f"no chunk where the index says (record opcode {opcode:#x})"
    if body + 9 != length:
        return f"its record is {body + 9} bytes long, the index says {length}"
    if (start, stop) != (index.message_start_time, index.message_end_time):
        return "its header's log times are not what the index says"
    if usize != index.uncompressed_size:
        return "its header's uncompressed size is not what the index says"
    return None


def _unindexed(f: IO[bytes], size: int, summary: Summary) -> list[str]:
    """The data section read through (records framed, chunks not opened): chunks the index
    does not name."""
    indexed = {c.chunk_start_offset for c in summary.chunk_indexes}
    f.seek(0)
    reader = StreamReader(f, emit_chunks=True, record_size_limit=size)
    found: list[str] = []
    at = len(MAGIC)
    try:
        for record in reader.records:
            if isinstance(record, Chunk) and at not in indexed:
                found.append(
                    f"a chunk at byte {at} (log time {record.message_start_time} to "
                    f"{record.message_end_time} ns) is not in the file's index: the summary "
                    "does not count its events"
                )
            if isinstance(record, DataEnd):
                break
            at = f.tell()
    except Exception as e:  # whatever the mcap library raises on a damaged record
        what = str(e) or type(e).__name__
        found.append(f"the data section does not read through after byte {at}: {what}")
    return found


def _chunk(number: int, index: ChunkIndex, why: str) -> str:
    return (
        f"chunk {number} (at byte {index.chunk_start_offset}, log time "
        f"{index.message_start_time} to {index.message_end_time} ns): {why}"
    )
