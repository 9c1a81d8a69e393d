"""Writing part of a file set to a new log: `miro log cut` (Miro's LogTruncate), `miro log
merge` and the window's Save as.

The events are copied as they are (log time, publish time, sequence number, CDR payload) in
the set's order, into a file laid out as the recorder lays one out (eventlog.writer: chunked,
zstd, indexed, a summary), so Foxglove and the `mcap` tools read it. Channels of the same
topic, encoding, schema and metadata in several files become one channel; equal schemas one
schema. The file is written under a temporary name next to the target and renamed when it is
complete: a failed or cancelled write leaves no half file, and never touches an input.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable

from mcap.writer import CompressionType, Writer

from miro_gen.eventlog.fileset import START, Event, FileSet, TopicName, at_time
from miro_gen.eventlog.logfile import Cancelled
from miro_gen.eventlog.reader import LogError, Topic
from miro_gen.eventlog.writer import CHUNK_BYTES, LIBRARY, PROFILE

PROGRESS_EVERY = 10_000  # events between calls of the progress callback


class _Output:
    """The new file's schemas and channels, registered as the events need them."""

    def __init__(self, writer: Writer) -> None:
        self.writer = writer
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[tuple[object, ...], int] = {}
        self._by_source: dict[tuple[int, int], int] = {}  # (file number, channel id) -> id

    def channel(self, event: Event) -> int:
        source = (event.key[1], event.topic.id)
        cid = self._by_source.get(source)
        if cid is None:
            cid = self._by_source[source] = self._register(event.topic)
        return cid

    def _register(self, topic: Topic) -> int:
        sid = 0
        if topic.schema_encoding or topic.schema:
            skey = (topic.schema_name, topic.schema_encoding, topic.schema)
            sid = self._schemas.get(skey, 0)
            if not sid:
                sid = self._schemas[skey] = self.writer.register_schema(*skey)
        metadata = {"domain": topic.domain, "type_name": topic.type_name}
        if topic.type_hash:
            metadata["type_hash"] = topic.type_hash
        ckey = (topic.topic, topic.message_encoding, sid, tuple(sorted(metadata.items())))
        cid = self._channels.get(ckey)
        if cid is None:
            cid = self._channels[ckey] = self.writer.register_channel(
                topic.topic, topic.message_encoding, sid, metadata
            )
        return cid


def write_selection(
    files: FileSet,
    path: str,
    start_ns: int | None = None,
    end_ns: int | None = None,
    keep: Callable[[TopicName], bool] | None = None,
    progress: Callable[[int], bool] | None = None,
) -> int:
    """Write the events of `files` from `start_ns` to `end_ns` (log times, both included;
    None: from the first, to the last) whose topic `keep` accepts, to a new log at `path`;
    how many. `progress(events written)` returning False cancels (Cancelled). LogError when
    an input cannot be read or the file cannot be written."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        fd, temp = tempfile.mkstemp(prefix=".miro-log-", suffix=".mcap", dir=folder)
    except OSError as e:
        raise LogError(f"cannot write in {folder}: {e.strerror or e}") from None
    written = 0
    try:
        with os.fdopen(fd, "wb") as out:
            writer = Writer(out, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
            writer.start(profile=PROFILE, library=LIBRARY)
            channels = _Output(writer)
            start = at_time(start_ns) if start_ns is not None else START
            for event in files.forward(start, end_ns):
                if keep is not None and not keep(event.name):
                    continue
                m = event.message
                writer.add_message(
                    channels.channel(event), m.log_time, m.data, m.publish_time, m.sequence
                )
                written += 1
                if progress is not None and written % PROGRESS_EVERY == 0 and not progress(written):
                    raise Cancelled("cancelled")
            writer.finish()  # type: ignore[no-untyped-call]
        os.chmod(temp, 0o644 & ~_umask())
        os.replace(temp, path)
    except OSError as e:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise LogError(f"cannot write {path}: {e.strerror or e}") from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise
    return written


def _umask() -> int:
    """The process's umask, read without changing it (os.umask would, for every thread)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o022
