"""Writing event logs: MCAP files with a channel per `domain/type` topic (DESIGN.md, "Logs").

Each channel has the message encoding `cdr` and, when the payload's generated type is known
here, a schema named after the type's scoped name (`Miro::ExampleEventIDL`) with the encoding
`omgidl` and the type's data schema as text, the only IDL Foxglove's parser accepts. Message
records carry the recorder's receive time (log time), the event's source stamp (publish time)
and its sequence number (its low 32 bits: MCAP's field is 32 bits wide).

The file is chunked, zstd-compressed and indexed. A chunk is closed when it is full or a second
old, and the file flushed then: a recorder killed outright leaves every closed chunk readable.
`finish()` writes the summary and indexes; call it on every way out.

What arrives is not trusted to fit the file: MCAP numbers channels with 16 bits, so topics
past the 65,535th are refused (counted in `refused`, the others recorded on), and a stamp
outside MCAP's unsigned 64 bits is recorded as 0, so that no record is ever half-written.
"""

from __future__ import annotations

import os
import time
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from miro_gen import __version__
from miro_gen.eventlog.types import topic_name
from miro_gen.runtime import registry
from miro_gen.transport.events.frames import RawEvent

PROFILE = ""  # no well-known MCAP profile describes omgidl/cdr logs
LIBRARY = f"miro-gen/{__version__}"
CHUNK_BYTES = 1 << 20
CHUNK_SECONDS = 1.0
MAX_CHANNELS = 0xFFFF  # MCAP's channel ids are 16 bits (0 is not one)
_U64 = 1 << 64


class LogWriter:
    """Appends events to a new MCAP file at `path`."""

    def __init__(self, path: str, chunk_seconds: float = CHUNK_SECONDS) -> None:
        self.path = path
        self._file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed by finish()
        # With the data section's CRC, `miro log info` sees a changed byte anywhere in the
        # chunks without opening them (eventlog/check.py).
        self._mcap = Writer(
            self._file,
            chunk_size=CHUNK_BYTES,
            compression=CompressionType.ZSTD,
            enable_data_crcs=True,
        )
        self._mcap.start(profile=PROFILE, library=LIBRARY)
        self._channels: dict[tuple[str, str, str], int] = {}  # (domain, type, hash) -> id
        self._schemas: dict[str, int] = {}  # type hash -> schema id (0: unknown type)
        self.unknown_types: set[tuple[str, str]] = set()  # (topic, hash) written without schema
        self.messages = 0
        self.refused = 0  # events of topics past MAX_CHANNELS, not recorded
        self.refused_topics: set[str] = set()  # their topics (the first 100 of them)
        self.chunk_seconds = chunk_seconds
        self._chunk_started = time.monotonic()
        self._pending = 0  # messages not yet in a closed chunk
        self.finished = False

    def _schema_id(self, type_hash: str) -> int:
        sid = self._schemas.get(type_hash)
        if sid is None:
            cls = registry.find(type_hash)
            if cls is None:
                sid = 0
            else:
                sid = self._mcap.register_schema(
                    cls._type_name, "omgidl", cls._data_schema.encode()
                )
            self._schemas[type_hash] = sid
        return sid

    def _channel_id(self, e: RawEvent) -> int:
        """The channel of the event's topic, registered if new; 0 when the file has no room."""
        key = (e.domain, e.type_name, e.type_hash)
        cid = self._channels.get(key)
        if cid is None:
            topic = topic_name(e.domain, e.type_name)
            if len(self._channels) >= MAX_CHANNELS:
                if len(self.refused_topics) < 100:
                    self.refused_topics.add(topic)
                return 0
            sid = self._schema_id(e.type_hash)
            if sid == 0:
                self.unknown_types.add((topic, e.type_hash))
            metadata = {"domain": e.domain, "type_name": e.type_name, "type_hash": e.type_hash}
            cid = self._mcap.register_channel(topic, "cdr", sid, metadata)
            self._channels[key] = cid
        return cid

    def write(self, events: list[RawEvent], received_ns: int) -> None:
        """Append the events of one frame, received at `received_ns`."""
        add = self._mcap.add_message
        written = 0
        for e in events:
            cid = self._channels.get((e.domain, e.type_name, e.type_hash)) or self._channel_id(e)
            if not cid:
                self.refused += 1
                continue
            stamp = e.stamp_ns if 0 <= e.stamp_ns < _U64 else 0
            add(cid, received_ns, e.data, stamp, e.seq & 0xFFFFFFFF)
            written += 1
        self.messages += written
        self._pending += written

    def tick(self) -> None:
        """Close the current chunk if it is older than `chunk_seconds` (call it periodically)."""
        now = time.monotonic()
        if self._pending and now - self._chunk_started >= self.chunk_seconds:
            self.flush()
        elif not self._pending:
            self._chunk_started = now

    def flush(self) -> None:
        """Close the current chunk and push the file's bytes to the operating system."""
        finalize: Any = getattr(self._mcap, "_Writer__finalize_chunk", None)
        if finalize is not None:  # mcap has no public call for this
            finalize()
        self._file.flush()
        self._pending = 0
        self._chunk_started = time.monotonic()

    def size(self) -> int:
        """Bytes written so far (closed chunks)."""
        try:
            return os.fstat(self._file.fileno()).st_size
        except (OSError, ValueError):
            return 0

    def finish(self) -> None:
        """Write the summary and indexes and close the file; safe to call twice."""
        if self.finished:
            return
        self.finished = True
        self._mcap.finish()  # type: ignore[no-untyped-call]
        self._file.close()
