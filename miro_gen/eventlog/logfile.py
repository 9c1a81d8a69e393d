"""One MCAP log opened for random access: where its events are, and reading them a piece at a
time, for the player, its window and the log tools that cut and merge.

A log is a list of *segments*: its chunks (or, in a file without chunks, runs of message
records), each with the log times of its first and last events and how many events of each
channel it holds. A finished file's segments come from its summary and chunk indexes alone,
read as `miro log info` reads them (eventlog.reader), so opening a large log costs what
reading its summary costs, and nothing of its data is read until it is played. A file
without a usable summary (its recorder was killed, the summary is damaged, a file without
chunks) is scanned once from the start, with progress and a way to cancel; the scan stops at
the last complete record.

`read(segment)` reads one segment with `os.pread`, so several threads (the play thread, the
window's event list, a plot) read the same file at once without sharing a file position.
A scan that meets a fault (a record cut off in the middle, a chunk that fails its checks)
stops there and says so in `fault`: the events before it are used.
Every chunk is checked as eventlog.chunks checks it (sizes capped, CRC, its header against
the index): a damaged chunk is a `LogError` naming it, never wrong events.
"""

from __future__ import annotations

import os
import struct
import threading
import time
from collections.abc import Callable

from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, Message, Schema
from mcap.summary import Summary

from miro_gen.eventlog.chunks import (
    MAX_CHUNK_BYTES,
    ChunkError,
    check_against_index,
    chunk_records,
    parse_chunk,
)
from miro_gen.eventlog.reader import MAGIC, LogError, LogReader, Topic
from miro_gen.eventlog.reader import _topic as topic_of  # the one way a channel becomes a Topic

_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length
_INDEX_RECORD = 15  # bytes of a message index record besides its entries (opcode ... length)
_INDEX_ENTRY = 16  # log time, offset
RUN_BYTES = 1 << 20  # message records outside chunks are read in runs of about this size
FUTURE_SLACK_NS = 1_000_000_000  # log times later than now by more than this are "in the future"
# progress(fraction done) -> False to cancel; called every few MiB while a file is scanned
Progress = Callable[[float], bool]


class SegmentError(LogError):
    """A segment of the file at `path` cannot be read (the message says why, and where)."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(message)
        self.path = path


class Cancelled(LogError):
    """Opening was cancelled (the progress callback said so)."""


class Segment:
    """A chunk of the file (`index` is its summary entry, None when found by a scan), or a run
    of message records outside chunks (`chunked` False)."""

    __slots__ = ("_counts", "chunked", "end_ns", "index", "length", "number", "offset", "start_ns")

    def __init__(
        self,
        number: int,  # 1, 2, ... in file order, for messages that name it
        offset: int,  # of the chunk record, or of the run's first record
        length: int,  # bytes of the chunk record's body, or of the run
        start_ns: int,
        end_ns: int,
        counts: dict[int, int] | None = None,  # None: told by the index when first asked
        index: ChunkIndex | None = None,
        chunked: bool = True,
    ) -> None:
        self.number = number
        self.offset = offset
        self.length = length
        self.start_ns = start_ns
        self.end_ns = end_ns
        self._counts = counts
        self.index = index
        self.chunked = chunked

    @property
    def counts(self) -> dict[int, int]:
        """Channel id -> events in the segment (for display, never trusted for more)."""
        if self._counts is None:
            self._counts = _index_counts(self.index) if self.index is not None else {}
        return self._counts


class LogFile:
    """A log opened for random access (`open`). `number` tells files of a set apart (it is
    part of each event's key); `warnings` says what the tools should tell the user."""

    def __init__(self, path: str, number: int, fd: int, size: int) -> None:
        self.path = path
        self.number = number
        self._fd = fd
        self.size = size
        self.topics: dict[int, Topic] = {}
        self.segments: list[Segment] = []
        self.count = 0
        self.first_ns = 0
        self.last_ns = 0
        self.indexed = False  # opened from its summary, without a scan
        self.warnings: list[str] = []
        # Where a scan had to stop (a record cut off, a damaged chunk): the events before it
        # are all there; the tools say so as an error, the window as a warning.
        self.fault: str | None = None
        self.closed = False
        self._io = threading.Lock()

    # ---- opening --------------------------------------------------------------------------------

    @classmethod
    def open(cls, path: str, number: int = 0, progress: Progress | None = None) -> LogFile:
        """The log at `path`, from its summary when it has a usable one, else by a scan.
        Raises LogError (Cancelled when `progress` returned False)."""
        with LogReader(path) as reader:  # the summary, its CRC checked; "not MCAP" refused
            summary = reader.summary
            topics = {t.id: t for t in reader.topics()} if summary is not None else {}
            reader_warning = reader.warning
        try:
            fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
        except OSError as e:
            raise LogError(f"cannot open: {e.strerror or e}") from None
        log = cls(path, number, fd, os.fstat(fd).st_size)
        try:
            stats = None if summary is None else summary.statistics
            if summary is not None and (
                summary.chunk_indexes or (stats is not None and not stats.message_count)
            ):
                log.topics = topics
                log._from_summary(summary)
            else:
                if reader_warning is not None:
                    log.warnings.append(reader_warning)
                log._scan(progress)
        except BaseException:
            log.close()
            raise
        log._check_times()
        return log

    def _from_summary(self, summary: Summary) -> None:
        """Segments from the chunk indexes (their counts told when first asked), totals from
        the statistics: nothing more is read."""
        self.indexed = True
        ordered = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        self.segments = [
            Segment(
                n,
                c.chunk_start_offset,
                c.chunk_length,
                c.message_start_time,
                c.message_end_time,
                None,
                c,
            )
            for n, c in enumerate(ordered, 1)
        ]
        stats = summary.statistics
        if stats is None:
            self._totals()
        else:
            self.count = stats.message_count
            self.first_ns, self.last_ns = stats.message_start_time, stats.message_end_time

    def _scan(self, progress: Progress | None) -> None:
        """Read the file from the start: its schemas, channels and segments."""
        schemas: dict[int, Schema] = {}
        at = len(MAGIC)
        chunks = 0
        run: _Run | None = None
        told = -RUN_BYTES * 4  # progress is told at the start, then every 4 MiB
        while at + _RECORD_HEAD.size <= self.size:
            if progress is not None and at - told >= RUN_BYTES * 4:
                told = at
                if not progress(at / self.size):
                    raise Cancelled("cancelled")
            opcode, length = _RECORD_HEAD.unpack(os.pread(self._fd, _RECORD_HEAD.size, at))
            body_at = at + _RECORD_HEAD.size
            if length > self.size - body_at:
                self.fault = f"truncated inside a record after byte {at}"
                break
            if opcode == Opcode.MESSAGE:
                if run is None:
                    run = _Run(at)
                body = os.pread(self._fd, min(length, 22), body_at)
                if len(body) == 22:
                    channel, _, log_time, _ = struct.unpack("<HIQQ", body)
                    run.add(channel, log_time, body_at + length)
                if run.end - run.offset >= RUN_BYTES:
                    self._add_run(run)
                    run = None
            else:
                if run is not None:
                    self._add_run(run)
                    run = None
                if opcode == Opcode.CHUNK:
                    chunks += 1
                    if not self._scan_chunk(chunks, at, length, schemas):
                        break
                elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                    body = os.pread(self._fd, length, body_at)
                    if not self._scan_definition(opcode, body, schemas):
                        break
                elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                    break
            at = body_at + length
        if run is not None:
            self._add_run(run)
        if progress is not None:
            progress(1.0)
        self._totals()

    def _scan_chunk(self, number: int, at: int, length: int, schemas: dict[int, Schema]) -> bool:
        """Add the chunk at `at`; False (and the fault said) when it fails its checks."""
        try:
            if length > MAX_CHUNK_BYTES + 4096:
                raise ChunkError(f"its record of {length} bytes is larger than a chunk may be")
            chunk = parse_chunk(os.pread(self._fd, length, at + _RECORD_HEAD.size))
            records = chunk_records(chunk)
        except ChunkError as e:
            self.fault = f"chunk {number} (at byte {at}) is damaged: {e}"
            return False
        counts: dict[int, int] = {}
        for record in records:
            if isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
            elif isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                self.topics.setdefault(record.id, topic_of(record, schemas.get(record.schema_id)))
        if counts:
            self.segments.append(
                Segment(
                    len(self.segments) + 1,
                    at,
                    length,
                    chunk.message_start_time,
                    chunk.message_end_time,
                    counts,
                )
            )
        return True

    def _scan_definition(self, opcode: int, body: bytes, schemas: dict[int, Schema]) -> bool:
        """A schema or channel record outside chunks, read through the chunk parser (an
        uncompressed pseudo-chunk of one record, bounds checked)."""
        data = _RECORD_HEAD.pack(opcode, len(body)) + body
        try:
            records = chunk_records(Chunk("", data, 0, 0, 0, len(data)))
        except ChunkError as e:
            self.fault = f"a schema or channel record is damaged: {e}"
            return False
        for record in records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                self.topics.setdefault(record.id, topic_of(record, schemas.get(record.schema_id)))
        return True

    def _add_run(self, run: _Run) -> None:
        if run.counts:
            self.segments.append(
                Segment(
                    len(self.segments) + 1,
                    run.offset,
                    run.end - run.offset,
                    run.first,
                    run.last,
                    dict(run.counts),
                    chunked=False,
                )
            )

    def _totals(self) -> None:
        segs = self.segments
        self.count = sum(sum(s.counts.values()) for s in segs)
        if segs:
            self.first_ns = min(s.start_ns for s in segs)
            self.last_ns = max(s.end_ns for s in segs)

    def _check_times(self) -> None:
        ahead = self.last_ns - time.time_ns()
        if self.segments and ahead > FUTURE_SLACK_NS:
            self.warnings.append(
                f"its times lie in the future (its last event {ahead / 1e9:.1f} s after now): "
                "the recording machine's clock was ahead of this one's?"
            )

    # ---- reading --------------------------------------------------------------------------------

    def read(self, segment: Segment) -> list[Message]:
        """The messages of `segment`, in file order (any thread). LogError when it is damaged
        or the file was closed meanwhile."""
        try:
            with self._io:  # only the reads: a close waits for them, decompressing does not
                if self.closed:
                    raise SegmentError(self.path, "the file was closed")
                if segment.chunked:
                    body = self._chunk_body(segment)
                else:
                    body = os.pread(self._fd, segment.length, segment.offset)
            if segment.chunked:
                chunk = parse_chunk(body)
                if segment.index is not None:
                    check_against_index(chunk, segment.index)
            else:
                chunk = Chunk("", body, 0, 0, 0, len(body))  # the records as they are
            records = chunk_records(chunk, messages_only=True)
        except ChunkError as e:
            raise SegmentError(
                self.path,
                f"chunk {segment.number} (at byte {segment.offset}, log time "
                f"{segment.start_ns} to {segment.end_ns} ns) is damaged: {e}",
            ) from None
        except OSError as e:
            raise SegmentError(self.path, f"cannot read: {e.strerror or e}") from None
        return [r for r in records if isinstance(r, Message)]

    def _chunk_body(self, segment: Segment) -> bytes:
        """The body of the chunk record at the segment's offset, its opcode and length checked."""
        head = os.pread(self._fd, _RECORD_HEAD.size, segment.offset)
        if len(head) != _RECORD_HEAD.size:
            raise ChunkError("cut off")
        opcode, length = _RECORD_HEAD.unpack(head)
        if opcode != Opcode.CHUNK:
            raise ChunkError(f"no chunk there (record opcode {opcode:#x})")
        body_at = segment.offset + _RECORD_HEAD.size
        if length > self.size - body_at:
            raise ChunkError(f"its length ({length} bytes) runs past the end of the file")
        if length > MAX_CHUNK_BYTES + 4096 and segment.index is None:
            raise ChunkError(f"its record of {length} bytes is larger than a chunk may be")
        return os.pread(self._fd, length, body_at)

    def close(self) -> None:
        """Close the file (after the reads under way); reading it then is a LogError."""
        with self._io:
            if not self.closed:
                self.closed = True
                os.close(self._fd)


class _Run:
    """Message records outside chunks, gathered into a segment while scanning."""

    def __init__(self, offset: int) -> None:
        self.offset = offset
        self.end = offset
        self.first = 0
        self.last = 0
        self.counts: dict[int, int] = {}

    def add(self, channel: int, log_time: int, end: int) -> None:
        if not self.counts:
            self.first = self.last = log_time
        self.first = min(self.first, log_time)
        self.last = max(self.last, log_time)
        self.counts[channel] = self.counts.get(channel, 0) + 1
        self.end = end


def _index_counts(index: ChunkIndex) -> dict[int, int]:
    """Events of each channel in a chunk, told by the sizes of its message index records (the
    summary's offsets of them): no byte of the chunk is read. For display; never trusted for
    more (a lying index gives wrong counts, clamped at 0, not wrong events)."""
    offsets = sorted((offset, cid) for cid, offset in index.message_index_offsets.items())
    if not offsets:
        return {}
    end = offsets[0][0] + index.message_index_length
    counts: dict[int, int] = {}
    for i, (offset, cid) in enumerate(offsets):
        following = offsets[i + 1][0] if i + 1 < len(offsets) else end
        counts[cid] = max(0, (following - offset - _INDEX_RECORD) // _INDEX_ENTRY)
    return counts
