"""ROS 2 services over DDS: a service answers requests on `rq<name>Request` on
`rr<name>Reply`; a client sends requests and waits for their replies.

Requests and replies carry the request header rmw_cyclonedds puts before each body (its
`serdata.hpp`, `Serialization.cpp`): after the encapsulation header, the client's 64-bit id and
the request's 64-bit sequence number, in the payload's byte order, then the body (whose
alignment is unchanged, 16 being a multiple of 8). A reply repeats its request's header; a
client takes the replies that carry its own id.

Fast DDS (rmw_fastrtps) instead relates a reply to its request through the RTPS sample
identity: a request has no header, and its reply must carry the request's writer GUID and
sequence number as inline QoS (`related_sample_identity`), which Cyclone DDS can neither write
nor read (ros2/rmw_cyclonedds#184). So a `Service` and a `Client` have their reader and writer
in the context's own RTPS participant (ros2/rtps), and each speaks to a peer as its vendor
expects: Fast DDS by sample identities, any other by the rmw_cyclonedds header (on this host).
"""

from __future__ import annotations

import logging
import secrets
import struct
import threading
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from miro_gen.ros2 import names
from miro_gen.ros2 import qos as ros_qos
from miro_gen.ros2.node import Node
from miro_gen.ros2.rtps import wire
from miro_gen.ros2.rtps.participant import Sample
from miro_gen.ros2.types import Message, dds_type, service_parts

log = logging.getLogger("miro.ros2")

Req = TypeVar("Req", bound=Message)
Res = TypeVar("Res", bound=Message)
HEADER_SIZE = 16  # client id (8 bytes) and sequence number (8 bytes)


class ServiceTimeout(TimeoutError):
    """No reply came in time."""


def with_header(cdr: bytes, client_id: int, seq: int) -> bytes:
    """A body's CDR (with its encapsulation header) with the request header put before it."""
    order = "<" if cdr[1] & 1 else ">"
    return cdr[:4] + struct.pack(order + "Qq", client_id, seq) + cdr[4:]


def split_header(data: bytes) -> tuple[int, int, bytes]:
    """(client id, sequence number, the body's CDR with its encapsulation header)."""
    if len(data) < 4 + HEADER_SIZE:
        raise ValueError(f"a request or reply of {len(data)} bytes has no request header")
    order = "<" if data[1] & 1 else ">"
    client_id, seq = struct.unpack_from(order + "Qq", data, 4)
    return client_id, seq, data[:4] + data[4 + HEADER_SIZE :]


class Service(Generic[Req, Res]):
    """Answers the requests of one ROS 2 service with `handler(request) -> response`; a
    request that does not decode is logged and dropped (its client times out).

    Its request reader and reply writer are in the context's own RTPS participant (ros2/rtps),
    not in cyclonedds: a Fast DDS client's request is related to its reply only through RTPS
    sample identities, which cyclonedds hides. A request from a Fast DDS participant (vendor
    eProsima) is answered with its sample identity as the reply's related_sample_identity; any
    other's carries rmw_cyclonedds' request header, which its reply repeats."""

    def __init__(
        self, node: Node, srv_type: type[Message], name: str, handler: Callable[[Req], Res],
        qos: ros_qos.QosProfile = ros_qos.SERVICES,
    ) -> None:  # fmt: skip
        self.name = node.resolve(name)
        self._request, self._response = service_parts(srv_type)
        self._handler = handler
        request_topic, reply_topic = names.service_to_dds(self.name)
        rtps, user_data = node.context.rtps, ros_qos.type_hash_user_data(srv_type._ros2_type_hash)
        self._writer = rtps.writer(reply_topic, dds_type(self._response), user_data)
        self._reader = rtps.reader(
            request_topic, dds_type(self._request), self._on_request, user_data
        )
        announcer = node.context.announcer
        announcer.add_endpoint(node.key, bytes(self._writer.guid), reader=False)
        announcer.add_endpoint(node.key, bytes(rtps.guid.prefix + self._reader.entity), True)

    def _on_request(self, sample: Sample) -> None:
        fast_dds = sample.vendor == wire.EPROSIMA
        try:
            if fast_dds:
                client_id, seq, body = 0, 0, sample.payload
            else:
                client_id, seq, body = split_header(sample.payload)
            request = self._request.deserialize(body)
        except Exception as e:
            log.warning("service %s: a request that does not decode was dropped: %s", self.name, e)
            return
        response = self._handler(request).serialize()
        if not fast_dds:  # to every reader of the client's participant; the client picks its own
            to = wire.Guid(sample.writer.prefix, wire.UNKNOWN_ENTITY)
            self._writer.write_to(to, with_header(response, client_id, seq))
            return
        # rmw_fastrtps names its client's reply reader in the request's related_sample_identity
        reader = sample.related_guid()
        if reader is None or reader.prefix != sample.writer.prefix:
            reader = wire.Guid(sample.writer.prefix, wire.UNKNOWN_ENTITY)
        identity = wire.related_sample_identity(sample.writer, sample.seq)
        self._writer.write_to(reader, response, identity)


class Client(Generic[Req, Res]):
    """Calls one ROS 2 service: `call(request, timeout)` → its response.

    Its request writer and reply reader are in the context's own RTPS participant (ros2/rtps):
    a request goes to each service's request reader the peers announced, as that reader's
    vendor expects it (a Fast DDS one: the bare body, our reply reader named in its
    related_sample_identity; any other: rmw_cyclonedds' request header); the first reply
    that names this client's request is the response."""

    def __init__(
        self, node: Node, srv_type: type[Message], name: str,
        qos: ros_qos.QosProfile = ros_qos.SERVICES,
    ) -> None:  # fmt: skip
        self.name = node.resolve(name)
        self._request, self._response = service_parts(srv_type)
        self._id = secrets.randbits(64)
        self._seq = 0
        self._lock = threading.Lock()
        self._pending: dict[tuple[str, int], list[Any]] = {}
        self._request_topic, self._reply_topic = names.service_to_dds(self.name)
        self._rtps = rtps = node.context.rtps
        user_data = ros_qos.type_hash_user_data(srv_type._ros2_type_hash)
        self._reader = rtps.reader(
            self._reply_topic, dds_type(self._response), self._on_reply, user_data
        )
        self._reader_guid = wire.Guid(rtps.prefix, self._reader.entity)
        self._writer = rtps.writer(self._request_topic, dds_type(self._request), user_data)
        announcer = node.context.announcer
        announcer.add_endpoint(node.key, bytes(self._reader_guid), reader=True)
        announcer.add_endpoint(node.key, bytes(self._writer.guid), reader=False)

    def service_is_ready(self) -> bool:
        """Whether a service's request reader and reply writer are both announced."""
        return bool(self._rtps.remote_readers(self._request_topic)) and (
            self._rtps.remote_writer_count(self._reply_topic) > 0
        )

    def wait_for_service(self, timeout: float = 10.0) -> bool:
        done = threading.Event()
        deadline = timeout
        while not self.service_is_ready():
            if deadline <= 0:
                return False
            done.wait(0.02)
            deadline -= 0.02
        return True

    def call(self, request: Req, timeout: float = 10.0) -> Res:
        body = request.serialize()
        slot: list[Any] = [threading.Event()]
        keys: list[tuple[str, int]] = []
        with self._lock:
            self._seq += 1
            seq = self._seq
            keys.append(("c", seq))
            self._pending[("c", seq)] = slot
        fast_qos = wire.related_sample_identity(self._reader_guid, wire.UNKNOWN_SEQ)
        try:
            for reader in self._rtps.remote_readers(self._request_topic):
                if self._rtps.vendor_of(reader.prefix) == wire.EPROSIMA:
                    with self._lock:  # the key is there before a reply can come
                        n = self._writer.write_to(reader, body, fast_qos)
                        keys.append(("f", n))
                        self._pending[("f", n)] = slot
                else:
                    self._writer.write_to(reader, with_header(body, self._id, seq))
            if not slot[0].wait(timeout):
                raise ServiceTimeout(f"service {self.name}: no reply within {timeout} s")
            return slot[1]  # type: ignore[no-any-return]
        finally:
            with self._lock:
                for key in keys:
                    self._pending.pop(key, None)

    def _on_reply(self, sample: Sample) -> None:
        if sample.vendor == wire.EPROSIMA:
            raw = sample.inline_qos.get(wire.PID_RELATED_SAMPLE_IDENTITY)
            raw = raw or sample.inline_qos.get(wire.PID_CUSTOM_RELATED_SAMPLE_IDENTITY)
            if raw is None or len(raw) < 24:
                return
            if raw[:16] not in (bytes(self._reader_guid), bytes(self._writer.guid)):
                return  # another client's reply
            high, low = struct.unpack_from("<iI", raw, 16)
            key, body = ("f", high << 32 | low), sample.payload
        else:
            try:
                client_id, seq, body = split_header(sample.payload)
            except ValueError:
                return
            if client_id != self._id:
                return  # another client's reply
            key = ("c", seq)
        with self._lock:
            slot = self._pending.get(key)
        if slot is None or slot[0].is_set():
            return  # a reply to a call that gave up, or a second reply
        try:
            slot.append(self._response.deserialize(body))
        except Exception as e:
            log.warning("service %s: a reply that does not decode was dropped: %s", self.name, e)
            return
        slot[0].set()
