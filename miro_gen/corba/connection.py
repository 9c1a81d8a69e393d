"""A TCP connection that carries GIOP messages: whole messages in, whole messages out.

Reading reassembles fragmented messages (`fragments.Reassembly`) and checks sizes against a
limit before anything is allocated. This is the client's side, which reads on the calling
thread; the server's connections are read by one thread for all (`server_io`).

A peer that is not speaking GIOP is recognised: a ZeroMQ peer (a `miro naming` or a miro-gen
server) greets every connection with ZMTP's signature, which is reported as such instead of as
garbage.
"""

from __future__ import annotations

import contextlib
import socket
import threading

from miro_gen.corba import giop
from miro_gen.corba.fragments import Reassembly
from miro_gen.corba.giop import HEADER_SIZE, GiopError, Header, MsgType

DEFAULT_MAX_MESSAGE = 64 << 20  # bytes a message may have, its fragments together
_RECV = 65536


class NotGiop(GiopError):
    """The peer speaks something else; `zmq` when it is ZeroMQ."""

    def __init__(self, message: str, zmq: bool) -> None:
        super().__init__(message)
        self.zmq = zmq


def is_zmtp(data: bytes) -> bool:
    """Whether `data` starts like a ZMTP 3 greeting (0xFF, 8 bytes of padding, 0x7F)."""
    return len(data) >= 1 and data[0] == 0xFF and (len(data) < 10 or data[9] == 0x7F)


def greets_with_zmtp(peer: str, timeout: float = 0.5) -> bool:
    """Whether the listener at `peer` (HOST:PORT) greets a silent new connection with ZMTP's
    signature. A ZeroMQ peer that enforces security resets a connection whose first bytes are
    GIOP before its own greeting can be read, so a reset alone does not tell it apart."""
    host, _, port = peer.rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout) as sock:
            sock.settimeout(timeout)
            return is_zmtp(sock.recv(16))
    except (OSError, ValueError):
        return False


class GiopConnection:
    """One end of a TCP connection carrying GIOP. `read_message` is for one thread at a time;
    `send` may be called from any thread."""

    def __init__(self, sock: socket.socket, peer: str, max_message: int = DEFAULT_MAX_MESSAGE):
        with contextlib.suppress(OSError):  # not TCP (a socket pair in a test)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = sock
        self.peer = peer  # HOST:PORT, for messages
        self.max_message = max_message
        self._buf = bytearray()
        self._send_lock = threading.Lock()
        self._fragments = Reassembly(max_message)
        self.closed = False

    # ---- sending --------------------------------------------------------------------------------

    def send(self, data: bytes) -> None:
        with self._send_lock:
            self.sock.sendall(data)

    def send_quietly(self, data: bytes) -> None:
        """Send, ignoring a connection that is already gone (for CloseConnection, MessageError)."""
        with contextlib.suppress(OSError):
            self.send(data)

    # ---- receiving ------------------------------------------------------------------------------

    def _fill(self, n: int) -> None:
        """Read until at least `n` bytes are buffered; EOFError when the peer closes first."""
        while len(self._buf) < n:
            chunk = self.sock.recv(max(_RECV, n - len(self._buf)))
            if not chunk:
                raise EOFError(f"{self.peer} closed the connection")
            if not self._buf and is_zmtp(chunk):
                raise NotGiop(f"{self.peer} speaks ZeroMQ, not GIOP", zmq=True)
            self._buf += chunk

    def _read(self, n: int) -> bytes:
        self._fill(n)
        data = bytes(self._buf[:n])
        del self._buf[:n]
        return data

    def read_message(self) -> tuple[Header, bytes]:
        """The next whole message (fragments reassembled): its header and all its bytes,
        header included. GiopError for a protocol error, EOFError when the peer has closed,
        OSError (socket.timeout included) from the socket."""
        if not self._buf:  # the common case: one recv, one whole message, no copy
            chunk = self.sock.recv(_RECV)
            if not chunk:
                raise EOFError(f"{self.peer} closed the connection")
            if chunk[:4] == giop.MAGIC:
                h = giop.whole_message_header(chunk)
                if h is not None:
                    return h, chunk
            if is_zmtp(chunk):
                raise NotGiop(f"{self.peer} speaks ZeroMQ, not GIOP", zmq=True)
            self._buf += chunk
        while True:
            self._fill(HEADER_SIZE)
            head = bytes(self._buf[:HEADER_SIZE])
            if head[:4] != giop.MAGIC:
                raise NotGiop(f"{self.peer} sent {head[:4]!r}, which is not GIOP", zmq=False)
            h = giop.read_header(head)
            if h.size > self.max_message:
                raise GiopError(
                    f"{self.peer} sent a {h.size}-byte message; the limit is {self.max_message}"
                )
            msg = self._read(HEADER_SIZE + h.size)
            whole = self._reassemble(h, msg)
            if whole is not None:
                return whole

    def _reassemble(self, h: Header, msg: bytes) -> tuple[Header, bytes] | None:
        if h.type == MsgType.FRAGMENT:
            whole = self._fragments.add(h, msg)
            return None if whole is None else (whole[0], bytes(whole[1]))
        if not h.more:
            return h, msg
        self._fragments.begin(h, msg)
        return None

    def close(self) -> None:
        self.closed = True
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
