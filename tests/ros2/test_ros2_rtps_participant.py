"""miro_gen/ros2/rtps/participant.py between two of our own participants over loopback UDP:
they find each other by SPDP on the participant-index ports, match by SEDP, and a sample goes
from a writer to the remote reader with its sequence number and inline QoS; malformed
datagrams on the way are dropped without stopping the participant. (Against Fast DDS:
tests/ros2/test_ros2_runtime.py.)"""

from __future__ import annotations

import random
import socket

from loopback import eventually

from miro_gen.ros2.rtps import wire
from miro_gen.ros2.rtps.participant import RtpsParticipant, Sample


def test_two_participants_match_and_a_sample_keeps_its_identity() -> None:
    domain = random.randint(200, 230)
    got: list[Sample] = []

    def take(sample: Sample) -> None:
        got.append(sample)

    a, b = RtpsParticipant(domain), RtpsParticipant(domain)
    try:
        assert a.port != b.port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as junk:
            for raw in (b"", b"RTPS", b"RTPS\x02\x03\x01\x0f" + bytes(12) + b"\x15\x01\xff\xff"):
                junk.sendto(raw, ("127.0.0.1", a.port))
        reader = a.reader("rq/addRequest", "pkg::srv::dds_::Add_Request_", take)
        writer = b.writer("rq/addRequest", "pkg::srv::dds_::Add_Request_")
        eventually(lambda: bool(b.remote_readers("rq/addRequest")), 30, lambda: "no SEDP from a")
        eventually(lambda: a.remote_writer_count("rq/addRequest") == 1, 30, lambda: "none from b")
        (remote,) = b.remote_readers("rq/addRequest")
        assert remote == wire.Guid(a.prefix, reader.entity)
        qos = wire.related_sample_identity(wire.Guid(b.prefix, b"\x00\x00\x09\x04"), 77)
        payload = b"\x00\x01\x00\x00" + bytes(range(16))
        for _ in range(3):
            writer.write_to(remote, payload, qos)
        eventually(lambda: len(got) == 3, 30, lambda: f"{len(got)} of 3 samples")
        # a sample whose datagram is lost (its HEARTBEAT with it) is sent again
        send, lost = b.send_user, []
        b.send_user = lambda prefix, msg, builtin=False: lost.append(msg)  # type: ignore[method-assign]
        writer.write_to(remote, payload, qos)
        b.send_user = send  # type: ignore[method-assign]
        assert len(lost) == 1
        eventually(lambda: len(got) == 4, 30, lambda: "the lost sample was not sent again")
        assert [s.seq for s in got] == [1, 2, 3, 4]
        assert {s.writer for s in got} == {writer.guid}
        assert all(s.payload == payload for s in got)
        assert got[0].related_guid() == wire.Guid(b.prefix, b"\x00\x00\x09\x04")
        assert got[0].vendor == wire.VENDOR_ID
        # a participant that closes says so: the other forgets its endpoints at once
        a.close()
        eventually(lambda: not b.remote_readers("rq/addRequest"), 30, lambda: "a not forgotten")
    finally:
        a.close()
        b.close()
