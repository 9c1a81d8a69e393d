"""Reading event logs, finished or not, without ever failing with a traceback.

A finished file is read through its summary and indexes, in log-time order. A file without a
summary (its recorder was killed) is read from the start up to the last complete record; that
is an *unfinished* file: its events are all there up to the last closed chunk, and the tools
say so with a warning. Anything else that does not parse (not MCAP, a chunk that does not
decompress, a record cut in the middle) is an error: `LogError`, raised when the file is opened
or, for a fault further in, after the events before it were delivered.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import IO

from mcap.exceptions import EndOfFile
from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

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


def _topic(channel: Channel, schema: Schema | None) -> Topic:
    meta = channel.metadata
    domain, _, type_name = channel.topic.rpartition("/")
    type_hash = meta.get("type_hash", "")
    if not type_hash and schema is not None and schema.encoding == "omgidl":
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
        self.summary = self._read_summary()
        self.unfinished = self.summary is None
        self._topics: dict[int, Topic] | None = None
        if self.summary is not None:
            self._topics = {
                cid: _topic(ch, self.summary.schemas.get(ch.schema_id))
                for cid, ch in self.summary.channels.items()
            }

    def _read_summary(self) -> Summary | None:
        try:
            self._file.seek(0)
            summary = SeekingReader(self._file).get_summary()
        except Exception:  # no footer or a damaged one: read it as unfinished
            return None
        return summary

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
        assert self._topics is not None
        self._file.seek(0)
        try:
            reader = SeekingReader(self._file)
            it = reader.iter_messages(
                topics=list(wanted) if wanted is not None else None,
                start_time=start_ns,
                end_time=end_ns,
                log_time_order=True,
            )
            for _, channel, message in it:
                yield self._topics[channel.id], message
        except LogError:
            raise
        except Exception as e:
            raise LogError(f"corrupt data: {_describe(e)}") from None

    def _streamed(
        self, wanted: set[str] | None, start_ns: int | None, end_ns: int | None
    ) -> Iterator[tuple[Topic, Message]]:
        f = self._file
        size = os.fstat(f.fileno()).st_size
        f.seek(0)
        schemas: dict[int, Schema] = {}
        topics: dict[int, Topic] = {}
        complete = len(MAGIC)  # where the last record read whole ends
        try:
            for record in StreamReader(f).records:
                complete = f.tell()
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
            where = "truncated inside a record" if f.tell() >= size else "corrupt data"
            raise LogError(f"{where} after byte {complete}: {_describe(e)}") from None
        finally:
            if self._topics is None:
                self._topics = dict(topics)


def _describe(e: BaseException) -> str:
    text = str(e)
    return f"{type(e).__name__}: {text}" if text else type(e).__name__
