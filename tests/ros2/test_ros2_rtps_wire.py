"""The RTPS bytes of miro_gen/ros2/rtps/wire.py: what we write, byte for byte where RTPS 2.3
fixes it, and what we read back, including messages laid out as Fast DDS lays them out."""

from __future__ import annotations

import struct

import pytest

from miro_gen.ros2.rtps import wire
from miro_gen.ros2.rtps.wire import Guid

PREFIX = bytes(range(1, 13))
FAST_PREFIX = b"\x01\x0f" + bytes(range(20, 30))
WRITER = b"\x00\x00\x14\x03"
READER = b"\x00\x00\x13\x04"


def test_a_reply_carries_the_requests_identity_as_pid_0x0083() -> None:
    """The inline QoS Fast DDS reads from any vendor (0x800f only from eProsima and RTI):
    GUID, then the sequence number as high int32 and low uint32."""
    qos = wire.related_sample_identity(Guid(FAST_PREFIX, WRITER), (3 << 32) + 7)
    assert qos[:4] == b"\x83\x00\x18\x00"
    assert qos[4:20] == FAST_PREFIX + WRITER
    assert struct.unpack("<iI", qos[20:28]) == (3, 7)
    assert qos[28:] == b"\x01\x00\x00\x00"  # the sentinel


def test_data_lays_out_its_header_inline_qos_and_payload() -> None:
    payload = b"\x00\x01\x00\x00" + struct.pack("<q", 42)
    qos = wire.related_sample_identity(Guid(FAST_PREFIX, WRITER), 5)
    sub = wire.data(READER, b"\x00\x00\x01\x03", 9, payload, qos)
    kind, flags, size = struct.unpack_from("<BBH", sub)
    assert (kind, flags) == (wire.DATA, 0x01 | 0x02 | 0x04)  # E, Q (inline QoS), D (data)
    assert size == len(sub) - 4
    assert sub[4:8] == b"\x00\x00\x10\x00"  # extra flags; 16 octets to the inline QoS
    assert sub[8:12] == READER and sub[12:16] == b"\x00\x00\x01\x03"
    assert struct.unpack_from("<iI", sub, 16) == (0, 9)
    assert sub[24 : 24 + len(qos)] == qos
    assert sub[24 + len(qos) :] == payload


def test_what_we_write_reads_back() -> None:
    payload = b"\x00\x01\x00\x00\x01\x00\x00\x00"
    qos = wire.related_sample_identity(Guid(PREFIX, WRITER), 2)
    msg = (
        wire.header(PREFIX)
        + wire.info_dst(FAST_PREFIX)
        + wire.info_ts(1700000000.5)
        + wire.data(READER, WRITER, 2, payload, qos)
        + wire.heartbeat(READER, WRITER, 2, 4, 7)
        + wire.acknack(READER, WRITER, 3, [3, 40, 100], 8)
        + wire.gap(READER, WRITER, 1, 2)
    )
    data, hb, ack, gap = list(wire.read_message(msg))
    assert data.kind == wire.DATA and data.source == PREFIX and data.vendor == wire.VENDOR_ID
    assert data.destination == FAST_PREFIX
    assert (data.reader, data.writer, data.seq, data.payload) == (READER, WRITER, 2, payload)
    assert data.inline_qos == {wire.PID_RELATED_SAMPLE_IDENTITY: qos[4:28]}
    assert (hb.kind, hb.first, hb.last, hb.final) == (wire.HEARTBEAT, 2, 4, False)
    assert (ack.kind, ack.base, ack.missing, ack.final) == (wire.ACKNACK, 3, [3, 40, 100], False)
    assert gap.irrelevant == [1]


def test_an_acknack_without_missing_numbers_is_final_and_has_no_bitmap() -> None:
    sub = wire.acknack(READER, WRITER, 5, [], 1)
    assert sub[1] == 0x03  # E, F
    assert struct.unpack_from("<iII", sub, 12) == (0, 5, 0)
    (ack,) = wire.read_message(wire.header(PREFIX) + sub)
    assert (ack.base, ack.missing, ack.final) == (5, [], True)


def test_a_fast_dds_request_with_its_inline_qos_is_read() -> None:
    """A request as rmw_fastrtps writes it (seen on loopback from Kilted's Fast DDS):
    INFO_TS, then DATA with the client's reply reader in both related-identity PIDs."""
    identity = FAST_PREFIX + READER + struct.pack("<iI", -1, 0)
    qos = struct.pack("<HH", 0x0083, 24) + identity + struct.pack("<HH", 0x800F, 24) + identity
    body = struct.pack("<HH", 0, 16) + b"\x00\x00\x02\x04" + WRITER + struct.pack("<iI", 0, 1)
    body += qos + b"\x01\x00\x00\x00" + b"\x00\x01\x00\x00\x01\x00\x00\x00"
    msg = b"RTPS\x02\x03\x01\x0f" + FAST_PREFIX + struct.pack("<BBHiI", 9, 1, 8, 1, 2)
    msg += struct.pack("<BBH", wire.DATA, 0x07, len(body)) + body
    (data,) = wire.read_message(msg)
    assert (data.vendor, data.source, data.writer, data.seq) == (
        wire.EPROSIMA,
        FAST_PREFIX,
        WRITER,
        1,
    )
    assert data.inline_qos[0x0083] == identity and data.inline_qos[0x800F] == identity
    assert data.payload == b"\x00\x01\x00\x00\x01\x00\x00\x00"


def test_a_big_endian_submessage_is_read() -> None:
    body = READER + WRITER + struct.pack(">iIiIi", 0, 1, 0, 6, 3)
    msg = wire.header(FAST_PREFIX) + struct.pack(">BBH", wire.HEARTBEAT, 0x02, len(body)) + body
    (hb,) = wire.read_message(msg)
    assert (hb.first, hb.last, hb.final) == (1, 6, True)


def test_spdp_and_sedp_data_read_back() -> None:
    spdp = wire.spdp_data(PREFIX, 7, 40000, 40001, b"enclave=/;")
    assert spdp[:4] == wire.PL_CDR_LE
    items = list(wire.read_param_items(spdp[4:]))
    params = dict(items)
    assert params[wire.PID_PARTICIPANT_GUID] == PREFIX + wire.PARTICIPANT
    assert struct.unpack("<I", params[wire.PID_DOMAIN_ID]) == (7,)
    assert wire.read_locators(items, wire.PID_METATRAFFIC_UNICAST_LOCATOR) == [("127.0.0.1", 40000)]
    assert wire.read_locators(items, wire.PID_DEFAULT_UNICAST_LOCATOR) == [("127.0.0.1", 40001)]
    guid = Guid(PREFIX, b"\x00\x00\x01\x03")
    sedp = wire.payload_params(wire.sedp_data(guid, "rr/addReply", "pkg::srv::dds_::X_Response_"))
    assert sedp[wire.PID_ENDPOINT_GUID] == bytes(guid)
    assert wire.read_string(sedp[wire.PID_TOPIC_NAME]) == "rr/addReply"
    assert wire.read_string(sedp[wire.PID_TYPE_NAME]) == "pkg::srv::dds_::X_Response_"
    assert struct.unpack("<i", sedp[wire.PID_RELIABILITY][:4]) == (wire.RELIABLE,)


def test_the_spdp_ports_follow_rtps() -> None:
    assert wire.spdp_port(0, 0) == 7410
    assert wire.spdp_port(1, 2) == 7664


@pytest.mark.parametrize(
    "raw",
    [
        b"",
        b"RTPX" + bytes(16),
        wire.header(PREFIX) + struct.pack("<BBH", wire.DATA, 1, 200) + bytes(20),
        wire.header(PREFIX)
        + struct.pack("<BBH", wire.ACKNACK, 1, 28)
        + READER
        + WRITER
        + struct.pack("<iII", 0, 1, 5000)
        + bytes(8),
    ],
    ids=["empty", "not-rtps", "overrun", "acknack-bitmap-overrun"],
)
def test_malformed_messages_raise_rtps_error(raw: bytes) -> None:
    with pytest.raises(wire.RtpsError):
        list(wire.read_message(raw))


def test_a_parameter_list_that_overruns_or_has_no_sentinel_is_refused() -> None:
    with pytest.raises(wire.RtpsError):
        list(wire.read_param_items(struct.pack("<HH", 0x0005, 40) + bytes(8)))
    with pytest.raises(wire.RtpsError):
        list(wire.read_param_items(wire.param(0x0005, b"abcd")))


def test_a_disposal_names_its_key_and_is_read_as_gone() -> None:
    guid = Guid(PREFIX, wire.PARTICIPANT)
    sub = wire.data(wire.SPDP_READER, wire.SPDP_WRITER, 2, b"", wire.disposal(guid))
    assert sub[1] == 0x03  # E, Q: no data
    (data,) = wire.read_message(wire.header(PREFIX) + sub)
    assert data.payload == b""
    assert wire.disposed_key(data) == bytes(guid)
    alive = wire.data(wire.SPDP_READER, wire.SPDP_WRITER, 1, wire.spdp_data(PREFIX, 0, 1, 2))
    (data,) = wire.read_message(wire.header(PREFIX) + alive)
    assert wire.disposed_key(data) is None
