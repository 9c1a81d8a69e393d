"""A minimal RTPS participant on loopback (UDP, one socket, one thread) for what the cyclonedds
wheel cannot do: take Fast DDS service requests with their sample identity and answer them with
the `related_sample_identity` inline QoS rmw_fastrtps needs (ros2/rmw_cyclonedds#184).

It announces itself by SPDP to the ports of participant indices 0 to 32 on 127.0.0.1 (as
LOCALHOST discovery does) and talks only with the Fast DDS participants (vendor eProsima) that
answer: it sends them the SEDP data of its endpoints (reliable: HEARTBEATs, ACKNACKs answered)
and reads their SEDP publications (which topic each writer writes). A reader takes the DATA
addressed to it, or unaddressed from a writer of its topic, acknowledges it and asks again for
what is missing; a writer sends each sample to one remote reader. DATA_FRAG (samples over
~64 KB) is not read. Handlers run on the participant's thread.
"""

from __future__ import annotations

import logging
import os
import secrets
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from miro_gen.ros2.rtps import wire
from miro_gen.ros2.rtps.wire import Guid

log = logging.getLogger("miro.ros2.rtps")

ANNOUNCE_PERIOD = 1.0
MAX_PARTICIPANT_INDEX = 32


@dataclass
class Sample:
    """A sample a reader took: who wrote it (its sample identity) and what came with it."""

    writer: Guid
    seq: int
    payload: bytes
    inline_qos: dict[int, bytes]
    vendor: bytes = b""  # the writer's participant's vendor id

    def related_guid(self) -> Guid | None:
        """The GUID of the writer's `related_sample_identity` (rmw_fastrtps puts its client's
        reply reader there), if the sample carries one."""
        raw = self.inline_qos.get(wire.PID_RELATED_SAMPLE_IDENTITY)
        raw = raw or self.inline_qos.get(wire.PID_CUSTOM_RELATED_SAMPLE_IDENTITY)
        return Guid.of(raw[:16]) if raw and len(raw) >= 24 else None


def _loopback(locators: list[tuple[str, int]]) -> list[tuple[str, int]]:
    return sorted({("127.0.0.1", port) for _, port in locators})


@dataclass
class _Peer:
    meta: list[tuple[str, int]]
    user: list[tuple[str, int]]
    vendor: bytes
    lease: float = 100.0  # seconds without an announcement before it is taken as gone
    seen: float = field(default_factory=time.monotonic)
    sedp_acked: dict[bytes, int] = field(default_factory=dict)


@dataclass
class _WriterState:
    """What a reader got from one remote writer: all below `low`, and `got` above."""

    low: int = 1
    got: set[int] = field(default_factory=set)
    count: int = 0

    def mark(self, seq: int) -> bool:
        if seq < self.low or seq in self.got:
            return False
        self.got.add(seq)
        self._advance()
        return True

    def skip(self, seqs: list[int]) -> None:
        for seq in seqs:
            if seq >= self.low:
                self.got.add(seq)
        self._advance()

    def heartbeat(self, first: int, last: int) -> list[int]:
        if self.low < first:
            self.low = first
            self.got = {s for s in self.got if s >= first}
        self._advance()
        return [s for s in range(self.low, min(last, self.low + 255) + 1) if s not in self.got]

    def _advance(self) -> None:
        while self.low in self.got:
            self.got.discard(self.low)
            self.low += 1


class Reader:
    def __init__(self, entity: bytes, topic: str, type_name: str,
                 handler: Callable[[Sample], None]) -> None:  # fmt: skip
        self.entity, self.topic, self.type_name, self.handler = entity, topic, type_name, handler
        self.writers: dict[bytes, _WriterState] = {}


class Writer:
    def __init__(self, participant: RtpsParticipant, entity: bytes, topic: str,
                 type_name: str) -> None:  # fmt: skip
        self._p = participant
        self.guid = Guid(participant.prefix, entity)
        self.topic, self.type_name = topic, type_name
        self._seq = 0
        self._hb = 0
        self._history: deque[tuple[int, bytes, bytes, bytes]] = deque(maxlen=64)
        self._unacked: dict[bytes, int] = {}  # a peer's prefix → the last number sent to it
        self._acked: dict[bytes, int] = {}  # a peer's prefix → all below acknowledged

    def write_to(self, reader: Guid, payload: bytes, inline_qos: bytes = b"") -> int:
        """Send one sample to one remote reader; its sequence number."""
        with self._p.lock:
            self._seq += 1
            seq = self._seq
            sub = wire.data(reader.entity, self.guid.entity, seq, payload, inline_qos)
            self._history.append((seq, reader.prefix, reader.entity, sub))
            self._unacked[reader.prefix] = seq
            self._send(reader, seq, [sub])
        return seq

    def acked(self, prefix: bytes, base: int) -> None:
        """A peer's reader acknowledged everything below `base`."""
        self._acked[prefix] = max(self._acked.get(prefix, 0), base)
        if self._unacked.get(prefix, base) < base:
            del self._unacked[prefix]

    def repeat(self) -> None:
        """Send again what a peer has not acknowledged yet (with its HEARTBEAT: a lost
        datagram would otherwise leave the peer waiting for good)."""
        for prefix in list(self._unacked):
            below = self._acked.get(prefix, 0)
            mine = [h for h in self._history if h[1] == prefix and h[0] >= below]
            if not mine:
                del self._unacked[prefix]  # gone from the history: nothing to send again
                continue
            self._send(Guid(prefix, wire.UNKNOWN_ENTITY), mine[0][0], [h[3] for h in mine])

    def _send(self, reader: Guid, first: int, subs: list[bytes]) -> None:
        self._hb += 1
        hb = wire.heartbeat(reader.entity, self.guid.entity, first, self._seq, self._hb)
        msg = wire.info_dst(reader.prefix) + wire.info_ts(time.time()) + b"".join(subs) + hb
        self._p.send_user(reader.prefix, msg)

    def resend(self, prefix: bytes, reader: bytes, missing: list[int]) -> None:
        mine = [h for h in self._history if h[1] == prefix and h[0] in missing]
        if mine:
            self._send(Guid(prefix, reader), mine[0][0], [h[3] for h in mine])


class RtpsParticipant:
    """Our participant: `writer(topic, type)`, `reader(topic, type, handler)`, `close()`."""

    def __init__(self, domain: int, user_data: bytes = b"") -> None:
        self.domain = domain
        self.prefix = (
            wire.VENDOR_ID + struct.pack(">H", os.getpid() & 0xFFFF) + secrets.token_bytes(8)
        )
        self.lock = threading.RLock()
        self._sock = self._bind(domain)
        self._sock.settimeout(0.2)
        self.port = self._sock.getsockname()[1]
        self._user_data = user_data
        self._peers: dict[bytes, _Peer] = {}
        self._readers: dict[bytes, Reader] = {}
        self._writers: dict[bytes, Writer] = {}
        self._sedp: dict[bytes, list[bytes]] = {wire.SEDP_PUB_WRITER: [], wire.SEDP_SUB_WRITER: []}
        self._next_key = 1
        self._topics: dict[bytes, str] = {}  # a remote writer's GUID → its topic
        self._sedp_reader = Reader(wire.SEDP_PUB_READER, "", "", self._on_publication)
        self._remote_readers: dict[bytes, str] = {}  # a remote reader's GUID → its topic
        self._sedp_sub_reader = Reader(wire.SEDP_SUB_READER, "", "", self._on_subscription)
        self._hb = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="miro-rtps", daemon=True)
        self._thread.start()

    @staticmethod
    def _bind(domain: int) -> socket.socket:
        """A socket on the metatraffic port of the first free participant index, where other
        participants' SPDP announcements (ours among them) arrive; else on any port."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for index in range(MAX_PARTICIPANT_INDEX + 1):
            try:
                sock.bind(("127.0.0.1", wire.spdp_port(domain, index)))
                return sock
            except OSError:
                continue
        sock.bind(("127.0.0.1", 0))
        return sock

    @property
    def guid(self) -> Guid:
        return Guid(self.prefix, wire.PARTICIPANT)

    def _entity(self, kind: int) -> bytes:
        key = self._next_key
        self._next_key += 1
        return struct.pack(">I", key)[1:] + bytes([kind])

    def writer(self, topic: str, type_name: str, user_data: bytes = b"") -> Writer:
        with self.lock:
            w = Writer(self, self._entity(wire.USER_WRITER_NO_KEY), topic, type_name)
            self._writers[w.guid.entity] = w
            self._sedp[wire.SEDP_PUB_WRITER].append(
                wire.sedp_data(w.guid, topic, type_name, True, user_data)
            )
        self._announce_sedp()
        return w

    def reader(self, topic: str, type_name: str, handler: Callable[[Sample], None],
               user_data: bytes = b"") -> Reader:  # fmt: skip
        with self.lock:
            r = Reader(self._entity(wire.USER_READER_NO_KEY), topic, type_name, handler)
            self._readers[r.entity] = r
            self._sedp[wire.SEDP_SUB_WRITER].append(
                wire.sedp_data(Guid(self.prefix, r.entity), topic, type_name, True, user_data)
            )
        self._announce_sedp()
        return r

    def close(self) -> None:
        """Stop, first telling the peers that this participant is gone (SPDP disposal), so
        that their graphs drop its endpoints at once rather than when its lease ends."""
        self._stop.set()
        self._thread.join(5)
        gone = wire.data(wire.SPDP_READER, wire.SPDP_WRITER, 2, b"", wire.disposal(self.guid))
        with self.lock:
            for peer in self._peers.values():
                self._sendto(wire.header(self.prefix) + gone, peer.meta)
        self._sock.close()

    # -- sending --

    def _sendto(self, msg: bytes, locators: list[tuple[str, int]]) -> None:
        for addr in locators:
            try:
                self._sock.sendto(msg, addr)
            except OSError as e:  # a full buffer or a port gone: the protocol repeats
                log.debug("rtps: send to %s failed: %s", addr, e)

    def send_user(self, prefix: bytes, msg: bytes, builtin: bool = False) -> None:
        """A message to a peer's user (or, for its builtin endpoints, metatraffic) locators."""
        peer = self._peers.get(prefix)
        if peer is not None:
            where = peer.meta if builtin else (peer.user or peer.meta)
            self._sendto(wire.header(self.prefix) + msg, where)

    def _announce_spdp(self) -> None:
        payload = wire.spdp_data(self.prefix, self.domain, self.port, self.port, self._user_data)
        sub = wire.data(wire.SPDP_READER, wire.SPDP_WRITER, 1, payload)
        msg = wire.header(self.prefix) + wire.info_ts(time.time()) + sub
        ports = [wire.spdp_port(self.domain, i) for i in range(MAX_PARTICIPANT_INDEX + 1)]
        self._sendto(msg, [("127.0.0.1", p) for p in ports])
        for peer in list(self._peers.values()):
            self._sendto(msg, peer.meta)

    def _announce_sedp(self, only: bytes | None = None, resend: bool = True) -> None:
        """Each builtin SEDP writer's samples (when `resend`) and a HEARTBEAT, to every peer."""
        with self.lock:
            for prefix, peer in list(self._peers.items()):
                if only is not None and prefix != only:
                    continue
                for writer, samples in self._sedp.items():
                    if not samples:
                        continue
                    reader = (
                        wire.SEDP_PUB_READER
                        if writer == wire.SEDP_PUB_WRITER
                        else wire.SEDP_SUB_READER
                    )
                    acked = peer.sedp_acked.get(writer, 0)
                    subs = [
                        wire.data(reader, writer, i + 1, s)
                        for i, s in enumerate(samples)
                        if resend and i + 1 > acked
                    ]
                    self._hb += 1
                    hb = wire.heartbeat(reader, writer, 1, len(samples), self._hb)
                    self._sendto(
                        wire.header(self.prefix) + wire.info_dst(prefix) + b"".join(subs) + hb,
                        peer.meta,
                    )

    # -- receiving --

    def _run(self) -> None:
        next_announce = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_announce:
                self._announce_spdp()
                self._announce_sedp(resend=False)
                with self.lock:
                    for writer in self._writers.values():
                        writer.repeat()
                self._expire()
                next_announce = now + ANNOUNCE_PERIOD
            try:
                raw = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                self._on_message(raw)
            except (wire.RtpsError, struct.error, UnicodeDecodeError) as e:
                log.debug("rtps: a malformed message was dropped: %s", e)
            except Exception:  # a handler's defect must not end the participant
                log.exception("rtps: handling a message failed")

    def _on_message(self, raw: bytes) -> None:
        for sub in wire.read_message(raw):
            if sub.source == self.prefix:
                continue
            if sub.destination and sub.destination != self.prefix:
                continue
            if sub.kind == wire.DATA and sub.writer == wire.SPDP_WRITER:
                self._on_spdp(sub)
            elif sub.kind == wire.DATA:
                self._on_data(sub)
            elif sub.kind == wire.HEARTBEAT:
                self._on_heartbeat(sub)
            elif sub.kind == wire.GAP:
                reader = self._reader_for(sub)
                if reader is not None:
                    key = bytes(Guid(sub.source, sub.writer))
                    reader.writers.setdefault(key, _WriterState()).skip(sub.irrelevant)
            elif sub.kind == wire.ACKNACK:
                self._on_acknack(sub)

    def _forget(self, key: bytes) -> None:
        """A peer's endpoint (16-byte GUID) or, with the participant's entity id, the whole
        participant and its endpoints, gone."""
        with self.lock:
            if key[12:] == wire.PARTICIPANT:
                self._peers.pop(key[:12], None)
                for known in (self._topics, self._remote_readers):
                    for guid in [g for g in known if g[:12] == key[:12]]:
                        del known[guid]
            else:
                self._topics.pop(key, None)
                self._remote_readers.pop(key, None)

    def _expire(self) -> None:
        now = time.monotonic()
        with self.lock:
            gone = [p for p, peer in self._peers.items() if now - peer.seen > peer.lease]
        for prefix in gone:
            log.debug("rtps: participant %s gone (lease expired)", prefix.hex())
            self._forget(prefix + wire.PARTICIPANT)

    def _on_spdp(self, sub: wire.Submessage) -> None:
        gone = wire.disposed_key(sub)
        if gone is not None:
            self._forget(gone[:12] + wire.PARTICIPANT)
            return
        if not sub.payload:
            return
        items = list(wire.read_param_items(sub.payload[4:], "<" if sub.payload[1] == 3 else ">"))
        params = dict(items)
        guid = params.get(wire.PID_PARTICIPANT_GUID)
        domain = params.get(wire.PID_DOMAIN_ID)
        if guid is None or (domain is not None and struct.unpack("<I", domain)[0] != self.domain):
            return
        # This host only: a peer's ports are reached on loopback whatever address it gives
        # (Fast DDS gives its interfaces' addresses even with LOCALHOST discovery).
        meta = _loopback(wire.read_locators(items, wire.PID_METATRAFFIC_UNICAST_LOCATOR))
        user = _loopback(wire.read_locators(items, wire.PID_DEFAULT_UNICAST_LOCATOR))
        prefix = guid[:12]
        lease = params.get(wire.PID_LEASE_DURATION)
        with self.lock:
            new = prefix not in self._peers
            if new:
                self._peers[prefix] = _Peer(meta, user, sub.vendor)
            peer = self._peers[prefix]
            peer.meta, peer.user, peer.seen = meta, user, time.monotonic()
            if lease is not None and len(lease) >= 8:
                peer.lease = max(1.0, struct.unpack("<iI", lease[:8])[0] + 1.0)
        if new:
            log.debug("rtps: participant %s at %s", prefix.hex(), meta)
            self._announce_spdp()
            self._announce_sedp(only=prefix)

    def _on_publication(self, sample: Sample) -> None:
        """A Fast DDS writer's SEDP data: remember its topic."""
        try:
            params = wire.payload_params(sample.payload)
            guid, topic = params[wire.PID_ENDPOINT_GUID], params[wire.PID_TOPIC_NAME]
            self._topics[guid[:16]] = wire.read_string(topic)
        except (KeyError, wire.RtpsError, struct.error, UnicodeDecodeError):
            return  # a disposal (no topic) or data we do not read

    def _on_subscription(self, sample: Sample) -> None:
        """A peer's reader's SEDP data: remember its topic."""
        try:
            params = wire.payload_params(sample.payload)
            guid, topic = params[wire.PID_ENDPOINT_GUID], params[wire.PID_TOPIC_NAME]
            self._remote_readers[guid[:16]] = wire.read_string(topic)
        except (KeyError, wire.RtpsError, struct.error, UnicodeDecodeError):
            return

    def remote_readers(self, topic: str) -> list[Guid]:
        """The peers' readers of `topic` (as their SEDP announced them)."""
        with self.lock:
            return [Guid.of(g) for g, t in self._remote_readers.items() if t == topic]

    def remote_writer_count(self, topic: str) -> int:
        with self.lock:
            return sum(1 for t in self._topics.values() if t == topic)

    def vendor_of(self, prefix: bytes) -> bytes:
        peer = self._peers.get(prefix)
        return peer.vendor if peer is not None else b""

    def _reader_for(self, sub: wire.Submessage) -> Reader | None:
        if sub.writer == wire.SEDP_PUB_WRITER:
            return self._sedp_reader
        if sub.writer == wire.SEDP_SUB_WRITER:
            return self._sedp_sub_reader
        if sub.reader != wire.UNKNOWN_ENTITY:
            return self._readers.get(sub.reader)
        topic = self._topics.get(sub.source + sub.writer)
        return next((r for r in self._readers.values() if r.topic == topic), None)

    def _on_data(self, sub: wire.Submessage) -> None:
        reader = self._reader_for(sub)
        if reader is None:
            return
        writer = Guid(sub.source, sub.writer)
        state = reader.writers.setdefault(bytes(writer), _WriterState())
        if not state.mark(sub.seq):
            return
        if reader in (self._sedp_reader, self._sedp_sub_reader):
            gone = wire.disposed_key(sub)
            if gone is not None:
                self._forget(gone)
                return
        if sub.payload:
            reader.handler(Sample(writer, sub.seq, sub.payload, sub.inline_qos, sub.vendor))

    def _on_heartbeat(self, sub: wire.Submessage) -> None:
        reader = self._reader_for(sub)
        if reader is None:
            return  # a builtin writer's (we read no SEDP) or another reader's
        state = reader.writers.setdefault(bytes(Guid(sub.source, sub.writer)), _WriterState())
        missing = state.heartbeat(sub.first, sub.last)
        if sub.final and not missing:
            return
        state.count += 1
        ack = wire.acknack(reader.entity, sub.writer, state.low, missing, state.count)
        builtin = sub.writer[3] & 0xC0 == 0xC0
        self.send_user(sub.source, wire.info_dst(sub.source) + ack, builtin)

    def _on_acknack(self, sub: wire.Submessage) -> None:
        with self.lock:
            peer = self._peers.get(sub.source)
            if sub.writer in self._sedp and peer is not None:
                peer.sedp_acked[sub.writer] = sub.base - 1
                if sub.missing:
                    self._announce_sedp(only=sub.source)
            elif sub.writer in self._writers:
                writer = self._writers[sub.writer]
                writer.acked(sub.source, sub.base)
                if sub.missing:
                    writer.resend(sub.source, sub.reader, sub.missing)
