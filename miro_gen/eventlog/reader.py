"""Reading event logs, finished or not, without ever failing with a traceback.

A finished file is read through its summary and indexes, in log-time order. A file without a
summary (its recorder was killed) is read from the start up to the last complete record; that
is an *unfinished* file: its events are all there up to the last closed chunk, and the tools
say so with a warning. Nothing in a file is trusted (eventlog.chunks): every chunk's CRC is
checked and its decompressed size capped, the summary's CRC too (a damaged summary is read
around, from the data, with a warning), and the data section's CRC when the file is read from
the start. Anything else that does not parse (not MCAP, a chunk that does not decompress or
does not match its CRC, a record cut in the middle) is an error: `LogError`, naming the chunk,
raised when the file is opened or, for a fault further in, after the events before it were
delivered.
"""

from __future__ import annotations

import heapq
import os
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import IO

from mcap.exceptions import EndOfFile, RecordLengthLimitExceeded
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, ChunkIndex, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

from miro_gen.eventlog.chunks import (
    ChunkError,
    check_against_index,
    chunk_records,
    read_chunk,
)

MAGIC = b"\x89MCAP0\r\n"


class LogError(Exception):
    """The file cannot be read (further): the message says why."""


@dataclass(frozen=True)
class Topic:
    """A channel of the log: events of one type from one domain."""

    id: int
    topic: str
    domain: str
    type_name: str
    type_hash: str
    schema_name: str
    schema_encoding: str
    schema: bytes
    message_encoding: str

    @property
    def ros2(self) -> bool:
        """Whether this is a ROS 2 topic of a rosbag2 file."""
        return self.schema_encoding in ROS2_SCHEMA_ENCODINGS


ROS2_SCHEMA_ENCODINGS = ("ros2msg", "ros2idl")  # rosbag2's (miro_gen/ros2/bag.py)


def _topic(channel: Channel, schema: Schema | None) -> Topic:
    """A channel as a topic: miro's `domain/type`; or, in a rosbag2 file, the ROS topic as its
    domain, the ROS type (`pkg/msg/Name`) and its RIHS01 hash."""
    meta = channel.metadata
    if schema is not None and schema.encoding in ROS2_SCHEMA_ENCODINGS:
        return Topic(
            channel.id, channel.topic, channel.topic, schema.name,
            meta.get("topic_type_hash", ""), schema.name, schema.encoding, schema.data,
            channel.message_encoding,
        )  # fmt: skip
    domain, _, type_name = channel.topic.rpartition("/")
    type_hash = meta.get("type_hash", "")
    if not type_hash and schema is not None and schema.encoding == "omgidl":
        import hashlib  # here: ours carry their hash, and OpenSSL costs `miro log info` 3 ms

        type_hash = hashlib.sha256(schema.data).hexdigest()  # as miro-idl makes them
    return Topic(
        channel.id,
        channel.topic,
        meta.get("domain", domain),
        meta.get("type_name", type_name),
        type_hash,
        schema.name if schema else "",
        schema.encoding if schema else "",
        schema.data if schema else b"",
        channel.message_encoding,
    )


class LogReader:
    """An MCAP event log opened for reading. `unfinished` tells, after reading, whether the
    file had no summary (a recorder that was killed)."""

    def __init__(self, path: str) -> None:
        self.path = path
        try:
            self._file: IO[bytes] = open(path, "rb")  # noqa: SIM115 - closed by close()
        except OSError as e:
            raise LogError(f"cannot open: {e.strerror or e}") from None
        if self._file.read(len(MAGIC)) != MAGIC:
            self._file.close()
            raise LogError("not an MCAP file")
        self._size = os.fstat(self._file.fileno()).st_size
        self.damaged_summary = False  # a summary whose CRC does not match: read without it
        self.summary = self._read_summary()
        self.unfinished = self.summary is None and not self.damaged_summary
        self._topics: dict[int, Topic] | None = None
        if self.summary is not None:
            self._topics = {
                cid: _topic(ch, self.summary.schemas.get(ch.schema_id))
                for cid, ch in self.summary.channels.items()
            }

    @property
    def warning(self) -> str | None:
        """What a tool should warn about after reading the file, or None."""
        if self.damaged_summary:
            return (
                "the file's summary (its index) is damaged: read from the data instead, "
                "whose chunks were checked"
            )
        if self.unfinished:
            return (
                "the file is unfinished (no summary: its recorder was killed?); read up to "
                "its last complete chunk"
            )
        return None

    def _read_summary(self) -> Summary | None:
        try:
            self._file.seek(0)
            summary = SeekingReader(self._file, record_size_limit=self._size).get_summary()
        except Exception:  # no footer or a damaged one: read it as unfinished
            return None
        if summary is not None and not self._summary_crc_matches():
            self.damaged_summary = True
            return None
        return summary

    def _summary_crc_matches(self) -> bool:
        """Whether the summary section has the CRC its footer says (0: none was written)."""
        footer = self._size - len(MAGIC) - 29  # opcode, length, start, offset start, CRC
        self._file.seek(footer + 9)
        start, _, crc = struct.unpack("<QQI", self._file.read(20))
        crc = int(crc)
        if crc == 0 or not len(MAGIC) <= start <= footer:
            return crc == 0
        self._file.seek(start)
        value, left = 0, footer + 25 - start  # up to the footer's CRC field
        while left > 0:
            piece = self._file.read(min(left, 1 << 20))
            if not piece:
                return False
            value = zlib.crc32(piece, value)
            left -= len(piece)
        return bool(value == crc)

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> LogReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def topics(self) -> list[Topic]:
        """The log's channels (an unfinished file is read through once to find them)."""
        if self._topics is None:
            for _ in self.messages():
                pass
        assert self._topics is not None
        return sorted(self._topics.values(), key=lambda t: t.topic)

    def span(self) -> tuple[int, int]:
        """Log times of the first and last events (0, 0 for none). An unfinished file is read
        through for them, so that a fault in it shows here (LogError)."""
        s = self.summary
        if s is not None and s.statistics is not None and s.statistics.message_count:
            return s.statistics.message_start_time, s.statistics.message_end_time
        first = last = None
        for _, m in self.messages():
            first = m.log_time if first is None else min(first, m.log_time)
            last = m.log_time if last is None else max(last, m.log_time)
        return (first or 0), (last or 0)

    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[tuple[Topic, Message]]:
        """The messages of `topics` (all when None) with start_ns <= log time < end_ns, in
        log-time order (file order for an unfinished file). Raises LogError at a fault."""
        wanted = None if topics is None else set(topics)
        if self.summary is not None and self.summary.chunk_indexes:
            yield from self._indexed(wanted, start_ns, end_ns)
        else:
            yield from self._streamed(wanted, start_ns, end_ns)

    def _indexed(
        self, wanted: set[str] | None, start_ns: int | None, end_ns: int | None
    ) -> Iterator[tuple[Topic, Message]]:
        """Chunks in the order of their first log time, their messages merged by log time:
        a chunk is opened when the next message due could be in it."""
        assert self._topics is not None and self.summary is not None
        topics = self._topics
        numbered = sorted(
            enumerate(self.summary.chunk_indexes, 1),
            key=lambda item: (item[1].message_start_time, item[1].chunk_start_offset),
        )
        chosen = [
            (n, c)
            for n, c in numbered
            if (start_ns is None or c.message_end_time >= start_ns)
            and (end_ns is None or c.message_start_time < end_ns)
        ]
        heap: list[tuple[int, int, int, Message]] = []
        order = 0
        next_chunk = 0
        while heap or next_chunk < len(chosen):
            if next_chunk < len(chosen) and (
                not heap or chosen[next_chunk][1].message_start_time <= heap[0][0]
            ):
                number, index = chosen[next_chunk]
                next_chunk += 1
                for m in self._chunk_messages(number, index):
                    topic = topics.get(m.channel_id)
                    if topic is None:
                        raise LogError(
                            f"chunk {number} at byte {index.chunk_start_offset}: a message of "
                            f"the unknown channel {m.channel_id}"
                        )
                    if (
                        (wanted is None or topic.topic in wanted)
                        and (start_ns is None or m.log_time >= start_ns)
                        and (end_ns is None or m.log_time < end_ns)
                    ):
                        heapq.heappush(heap, (m.log_time, order, m.channel_id, m))
                        order += 1
                continue
            _, _, channel_id, message = heapq.heappop(heap)
            yield topics[channel_id], message

    def _chunk_messages(self, number: int, index: ChunkIndex) -> list[Message]:
        try:
            chunk = read_chunk(self._file, index.chunk_start_offset, self._size)
            check_against_index(chunk, index)
            records = chunk_records(chunk, messages_only=True)
        except ChunkError as e:
            raise LogError(chunk_fault(number, index.chunk_start_offset, index, e)) from None
        return [r for r in records if isinstance(r, Message)]

    def _streamed(
        self, wanted: set[str] | None, start_ns: int | None, end_ns: int | None
    ) -> Iterator[tuple[Topic, Message]]:
        f = self._file
        size = os.fstat(f.fileno()).st_size
        f.seek(0)
        schemas: dict[int, Schema] = {}
        topics: dict[int, Topic] = {}
        complete = len(MAGIC)  # where the last record read whole ends
        number = 0
        reader = StreamReader(f, emit_chunks=True, validate_crcs=True, record_size_limit=size)
        try:
            for outer in reader.records:
                at = complete
                complete = f.tell()
                if isinstance(outer, Chunk):
                    number += 1
                    try:
                        records = chunk_records(outer)
                    except ChunkError as e:
                        raise LogError(chunk_fault(number, at, outer, e)) from None
                else:
                    records = [outer]
                for record in records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        topics[record.id] = _topic(record, schemas.get(record.schema_id))
                        if self._topics is None:
                            self._topics = {}
                        self._topics.setdefault(record.id, topics[record.id])
                    elif isinstance(record, Message):
                        topic = topics.get(record.channel_id)
                        if topic is None:
                            raise LogError(f"a message of the unknown channel {record.channel_id}")
                        if wanted is not None and topic.topic not in wanted:
                            continue
                        if start_ns is not None and record.log_time < start_ns:
                            continue
                        if end_ns is not None and record.log_time >= end_ns:
                            continue
                        yield topic, record
        except LogError:
            raise
        except Exception as e:
            if isinstance(e, EndOfFile) and complete == size:
                return  # unfinished, but cut between records: all it holds was read
            cut = f.tell() >= size or isinstance(e, RecordLengthLimitExceeded)  # past the end
            where = "truncated inside a record" if cut else "corrupt data"
            raise LogError(f"{where} after byte {complete}: {_describe(e)}") from None
        finally:
            if self._topics is None:
                self._topics = dict(topics)


def chunk_fault(number: int, offset: int, chunk: Chunk | ChunkIndex, e: ChunkError) -> str:
    """The error for a chunk that cannot be believed, naming it."""
    return (
        f"chunk {number} (at byte {offset}, log time {chunk.message_start_time} to "
        f"{chunk.message_end_time} ns) is damaged: {e}"
    )


def _describe(e: BaseException) -> str:
    text = str(e)
    return f"{type(e).__name__}: {text}" if text else type(e).__name__
