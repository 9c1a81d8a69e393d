"""Readers and writers of serialized samples: the bytes the generated classes encode (XCDR1,
header `00 01 00 00`) written as they are and taken as they come, on cyclonedds topics whose
type information is the generated type's shape (ros2/xtypes.py); and the thread that takes what
arrives and hands it to each reader's handler.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import (
    GuardCondition,
    InstanceState,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from miro_gen.ros2 import qos as ros_qos
from miro_gen.ros2 import typeinfo, xtypes
from miro_gen.ros2.domain import Participant, gid_of

log = logging.getLogger("miro.ros2")

# A sample as it arrives: its CDR bytes (with the encapsulation header) and cyclonedds' info.
Handler = Callable[[bytes, Any], None]
_TAKE_BATCH = 64
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any


class Topics:
    """The cyclonedds topics of a participant, one per DDS name (a topic's type is fixed)."""

    def __init__(self, participant: Participant) -> None:
        self.participant = participant
        self._topics: dict[str, tuple[str, Topic[Any]]] = {}
        self._lock = threading.Lock()

    def get(self, dds_name: str, data_schema: str) -> Topic[Any]:
        with self._lock:
            known = self._topics.get(dds_name)
            if known is not None:
                if known[0] != data_schema:
                    raise TypeError(f"DDS topic {dds_name!r} is used with another type already")
                return known[1]
            topic: Topic[Any] = Topic(
                self.participant.dds, dds_name, xtypes.idl_struct(data_schema)
            )
            typeinfo.hide(topic)
            self._topics[dds_name] = (data_schema, topic)
            return topic


class RawWriter:
    """A DDS writer of serialized samples."""

    def __init__(
        self, topics: Topics, dds_name: str, data_schema: str, profile: ros_qos.QosProfile,
        user_data: bytes = b"",
    ) -> None:  # fmt: skip
        topic = topics.get(dds_name, data_schema)
        self._writer: DataWriter[Any] = DataWriter(
            topics.participant.dds, topic, ros_qos.dds_qos(profile, user_data)
        )
        self.gid = gid_of(self._writer.get_guid())

    def write(self, data: bytes | bytearray) -> None:
        """Send one sample (CDR with its header); DDS wants a multiple of 4 bytes."""
        pad = -len(data) % 4
        ret = ddspy_write(self._writer._ref, bytes(data) + b"\0" * pad if pad else data)
        if ret < 0:
            raise OSError(f"DDS write failed ({ret})")

    def wait_for_acks(self, timeout: float) -> bool:
        """Whether every matched reliable reader acknowledged all written within `timeout` s."""
        return bool(self._writer.wait_for_acks(int(timeout * 1e9)))

    def matched(self) -> int:
        """How many readers this writer has matched."""
        return len(self._writer.get_matched_subscriptions())

    def close(self) -> None:
        self._writer._delete(self._writer._ref)


class RawReader:
    """A DDS reader of serialized samples; `dispatcher` calls `handler` with each."""

    def __init__(
        self, topics: Topics, dds_name: str, data_schema: str, profile: ros_qos.QosProfile,
        handler: Handler, dispatcher: Dispatcher, user_data: bytes = b"",
    ) -> None:  # fmt: skip
        topic = topics.get(dds_name, data_schema)
        self._reader: DataReader[Any] = DataReader(
            topics.participant.dds, topic, ros_qos.dds_qos(profile, user_data)
        )
        self.gid = gid_of(self._reader.get_guid())
        self.handler = handler
        self._dispatcher = dispatcher
        self.condition = ReadCondition(self._reader, _ANY)
        dispatcher.add(self)

    def take(self) -> list[tuple[bytes, Any]]:
        """What has arrived (at most a batch), with each sample's info; invalid samples (an
        instance's disposal) are left out."""
        ret = ddspy_take(self._reader._ref, _ANY, _TAKE_BATCH)
        if isinstance(ret, int):
            raise OSError(f"DDS take failed ({ret})")
        return [(data, info) for data, info in ret if info.valid_data]

    def matched(self) -> int:
        return len(self._reader.get_matched_publications())

    def matched_writers(self) -> list[Any]:
        """The DCPS endpoint data of the writers this reader matched."""
        out = []
        for handle in self._reader.get_matched_publications():
            data = self._reader.get_matched_publication_data(handle)
            if data is not None:
                out.append(data)
        return out

    def close(self) -> None:
        self._dispatcher.remove(self)
        self._reader._delete(self._reader._ref)


class Dispatcher:
    """One thread that waits on every reader of a participant and calls their handlers with
    what arrives, in order per reader. A handler that raises is logged; the others go on."""

    def __init__(self, participant: Participant) -> None:
        self._waitset = WaitSet(participant.dds)
        self._wake = GuardCondition(participant.dds)
        self._waitset.attach(self._wake)
        self._readers: dict[int, RawReader] = {}
        self._lock = threading.Lock()
        self._stopping = False
        self._thread = threading.Thread(target=self._run, name="miro-ros2-dispatch", daemon=True)
        self._thread.start()

    def add(self, reader: RawReader) -> None:
        with self._lock:
            self._readers[id(reader)] = reader
        self._waitset.attach(reader.condition)
        self._wake.set(True)

    def remove(self, reader: RawReader) -> None:
        with self._lock:
            self._readers.pop(id(reader), None)
        self._waitset.detach(reader.condition)

    def stop(self) -> None:
        self._stopping = True
        self._wake.set(True)
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5)

    def drain(self) -> None:
        """Stop the thread, then hand over what the readers hold still (a recorder's last
        messages), on the calling thread."""
        self.stop()
        with self._lock:
            readers = list(self._readers.values())
        for reader in readers:
            while samples := reader.take():
                for data, info in samples:
                    try:
                        reader.handler(data, info)
                    except Exception:
                        log.exception("a ROS 2 handler failed")

    def _run(self) -> None:
        while not self._stopping:
            self._waitset.wait(1_000_000_000)
            self._wake.set(False)
            with self._lock:
                readers = list(self._readers.values())
            for reader in readers:
                if self._stopping:
                    return
                try:
                    samples = reader.take()
                except OSError:  # the reader was closed meanwhile
                    continue
                for data, info in samples:
                    try:
                        reader.handler(data, info)
                    except Exception:
                        log.exception("a ROS 2 handler failed")
