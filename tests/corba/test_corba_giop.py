"""GIOP, IORs and TypeCodes without a C++ peer: byte-level checks of what miro_gen.corba writes
and reads, over real sockets against hand-made peers (big-endian messages, fragments, location
forwards, orderly closes, protocol errors, a ZeroMQ peer), and the GIOP reader fuzzed: a
malformed message is answered with MessageError or dropped, and the server goes on serving."""

from __future__ import annotations

import contextlib
import random
import socket
import struct
import threading
from collections.abc import Callable, Iterator
from typing import Any

import Miro
import Miro__POA
import pytest

from miro_gen import (
    BAD_OPERATION,
    COMM_FAILURE,
    MARSHAL,
    OBJECT_NOT_EXIST,
    TIMEOUT,
    TRANSIENT,
    UNKNOWN,
    CompletionStatus,
    nonblocking,
)
from miro_gen.corba import giop
from miro_gen.corba.anys import Any_, read_any, transcode, typecode_for, write_any
from miro_gen.corba.client import IIOPInvoker
from miro_gen.corba.connection import GiopConnection
from miro_gen.corba.giop import MsgType, ReplyStatus
from miro_gen.corba.ior import (
    IOR,
    CodeSets,
    CorbaName,
    UrlError,
    corbaloc,
    name_to_string,
    parse_name,
    parse_url,
    ref_from_ior,
)
from miro_gen.corba.server import IIOPServer
from miro_gen.corba.typecode import K, TypeCode, read_typecode, write_typecode
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

# The root context omniNames 4.2 printed on this project's build machine.
OMNINAMES_IOR = (
    "IOR:010000002b00000049444c3a6f6d672e6f72672f436f734e616d696e672f4e616d696e67436f6e7465"
    "78744578743a312e30000001000000000000006c000000010102000a0000003139322e302e322e3200bb6d0b"
    "0000004e616d6553657276696365000300000000000000080000000100000000545441010000001c0000000100"
    "000001000100010000000100010509010100010000000901010003545441080000009cac046b0100127a"
)


# ---- IORs and URLs --------------------------------------------------------------------------


def test_an_omninames_ior_reads_and_writes_back_the_same() -> None:
    ior = parse_url(OMNINAMES_IOR)
    assert isinstance(ior, IOR)
    assert ior.type_id == "IDL:omg.org/CosNaming/NamingContextExt:1.0"
    p = ior.iiop_profile()
    assert p is not None
    assert (p.version, p.host, p.port, p.key) == ((1, 2), "192.0.2.2", 28091, b"NameService")
    sets = CodeSets.decode(p.component(1) or b"")
    assert (sets.char_native, sets.char_conversion) == (0x00010001, (0x05010001,))
    assert sets.wchar_native == 0x00010109
    assert ior.to_string() == OMNINAMES_IOR
    ref = ref_from_ior(ior)
    assert ref.endpoint == "iiop://192.0.2.2:28091" and ref.key == b"NameService"


@pytest.mark.parametrize(
    ("url", "host", "port", "key", "version"),
    [
        ("corbaloc::robot:2809/NameService", "robot", 2809, b"NameService", (1, 2)),
        ("corbaloc:iiop:robot/NameService", "robot", 2809, b"NameService", (1, 2)),
        ("corbaloc:iiop:1.0@10.0.0.1:7/a%20b%2Fc", "10.0.0.1", 7, b"a b/c", (1, 0)),
        ("corbaloc:iiop:[::1]:9/k", "::1", 9, b"k", (1, 2)),
        ("iioploc://127.0.0.1:5000/NameService", "127.0.0.1", 5000, b"NameService", (1, 2)),
        ("corbaloc::a:1,:b:2/x", "a", 1, b"x", (1, 2)),
    ],
)
def test_corbaloc_urls(
    url: str, host: str, port: int, key: bytes, version: tuple[int, int]
) -> None:
    ior = parse_url(url)
    assert isinstance(ior, IOR)
    p = ior.iiop_profile()
    assert p is not None and (p.host, p.port, p.key, p.version) == (host, port, key, version)
    if "," in url:
        assert p.addresses() == [("a", 1), ("b", 2)]


def test_corbaname_urls_name_a_context_and_a_name() -> None:
    found = parse_url("corbaname::robot:2809#robot1/Laser.kind")
    assert isinstance(found, CorbaName)
    p = found.context.iiop_profile()
    assert p is not None and p.key == b"NameService" and found.name == "robot1/Laser.kind"
    assert parse_name(found.name) == [("robot1", ""), ("Laser", "kind")]
    tricky = [("a/b", "c.d"), ("e\\f", "")]
    assert parse_name(name_to_string(tricky)) == tricky
    iiopname = parse_url("iiopname://h:3/Root#x")
    assert isinstance(iiopname, CorbaName) and iiopname.name == "x"


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("http://x", "not an object reference"),
        ("corbaloc::host:1", "object key is missing"),
        ("corbaloc:rir:/NameService", "initial references"),
        ("corbaloc::host:99999/k", "out of range"),
        ("corbaloc:iiop:2.0@h:1/k", "unknown IIOP version"),
        ("IOR:0102", "does not decode"),
        ("IOR:xyz", "hex digits"),
    ],
)
def test_bad_urls_say_what_is_wrong(text: str, why: str) -> None:
    with pytest.raises(UrlError, match=why):
        parse_url(text)


def test_corbaloc_of_an_object() -> None:
    assert corbaloc("::1", 5, b"robot1/Ex ample") == "corbaloc:iiop:1.2@[::1]:5/robot1/Ex%20ample"


# ---- messages -------------------------------------------------------------------------------


@pytest.mark.parametrize("minor", [0, 1, 2])
@pytest.mark.parametrize("key", [b"k", b"key45", b"robot1/ExampleA"])
def test_requests_we_send_put_the_body_at_a_multiple_of_8(minor: int, key: bytes) -> None:
    body = b"\x01\x02\x03\x04\x05\x06\x07\x08"
    msg = giop.encode_request(minor, 77, True, key, "getData", body)
    h = giop.read_header(msg)
    assert (h.minor, h.type, h.size, h.little) == (minor, MsgType.REQUEST, len(msg) - 12, True)
    req = giop.decode_request(msg, h)
    assert (req.request_id, req.key, req.operation, req.response_expected) == (
        77,
        key,
        "getData",
        True,
    )
    assert req.body % 8 == 0 and msg[req.body :] == body
    template = giop.RequestTemplate(minor, True, key, "getData", True)
    assert template.message(77, body) == msg


def test_a_big_endian_request_and_reply_decode() -> None:
    op = b"setData\0"
    head = struct.pack(">IBxxxhxxI", 5, 3, 0, 3) + b"abc" + b"\0" + struct.pack(">I", len(op)) + op
    head += struct.pack(">I", 0)  # no service contexts
    head += b"\0" * (-(12 + len(head)) % 8)
    msg = (
        b"GIOP\x01\x02\x00\x00"
        + struct.pack(">I", len(head) + 16)
        + head
        + struct.pack(">dd", 1.5, -2)
    )
    h = giop.read_header(msg)
    req = giop.decode_request(msg, h)
    assert (h.little, req.request_id, req.key, req.operation) == (False, 5, b"abc", "setData")
    assert struct.unpack_from(">dd", msg, req.body) == (1.5, -2)
    reply = b"GIOP\x01\x00\x00\x01" + struct.pack(">IIII", 12, 0, 9, 1)
    r = giop.decode_reply(reply, giop.read_header(reply))
    assert (r.request_id, r.status, r.body) == (9, ReplyStatus.USER_EXCEPTION, 24)


@pytest.mark.parametrize(
    ("data", "why"),
    [
        (b"GIOX\x01\x02\x01\x00\0\0\0\0", "not a GIOP message"),
        (b"GIOP\x02\x00\x01\x00\0\0\0\0", "version 2.0"),
        (b"GIOP\x01\x00\x05\x00\0\0\0\0", "byte-order flag"),
        (b"GIOP\x01\x02\x01\x09\0\0\0\0", "message type 9"),
        (b"GIOP\x01\x00\x01\x07\0\0\0\0", "message type 7"),
    ],
)
def test_bad_headers_are_protocol_errors(data: bytes, why: str) -> None:
    with pytest.raises(giop.GiopError, match=why):
        giop.read_header(data)


@pytest.mark.parametrize("minor", [1, 2])
def test_fragments_are_reassembled(minor: int) -> None:
    whole = giop.encode_request(minor, 3, True, b"key", "op", bytes(range(40)))
    cut1, cut2 = 32, 48  # at multiples of 8, as GIOP wants
    first = bytearray(whole[:cut1])
    first[6] |= giop.FLAG_MORE
    struct.pack_into("<I", first, 8, cut1 - 12)

    def fragment(data: bytes, more: bool) -> bytes:
        fid = struct.pack("<I", 3) if minor == 2 else b""
        flags = 1 | (giop.FLAG_MORE if more else 0)
        return (
            b"GIOP"
            + bytes((1, minor, flags, 7))
            + struct.pack("<I", len(fid) + len(data))
            + fid
            + data
        )

    a, b = socket.socketpair()
    try:
        a.sendall(bytes(first) + fragment(whole[cut1:cut2], True) + fragment(whole[cut2:], False))
        h, msg = GiopConnection(b, "peer").read_message()
        assert (h.type, h.more) == (MsgType.REQUEST, False) and msg == whole
    finally:
        a.close()
        b.close()


# ---- a server, met over raw sockets ---------------------------------------------------------


class ExampleImpl(Miro__POA.Example):
    def __init__(self) -> None:
        self.value = Miro.ExampleStructIDL(1.0, 2.0)

    @nonblocking
    def getData(self) -> Miro.ExampleStructIDL:
        return self.value

    def setData(self, a: float, b: float) -> None:
        self.value = Miro.ExampleStructIDL(a, b)


@pytest.fixture
def served() -> Iterator[tuple[IIOPServer, IIOPInvoker]]:
    invoker = IIOPInvoker()
    server = IIOPServer(invoker)
    server.activate(ExampleImpl(), "robot/Example")
    yield server, invoker
    invoker.close()


def _exchange(server: IIOPServer, data: bytes) -> tuple[giop.Header, bytes] | None:
    """Send `data` on a new connection; the first message back, or None if it just closes."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as s:
        s.sendall(data)
        conn = GiopConnection(s, "server")
        try:
            return conn.read_message()
        except EOFError:
            return None


_KEY, _SET_DATA = b"robot/Example", b"setData\0"


def _set_data_by_hand(served: tuple[IIOPServer, IIOPInvoker], minor: int, head: bytes) -> None:
    """Send setData(0.5, 1e10) big-endian after a request header made by hand (its body
    aligned to the message's start, as GIOP lays it out) and check that it was served."""
    server, invoker = served
    body = b"\0" * (-(12 + len(head)) % 8) + struct.pack(">dd", 0.5, 1e10)
    size = struct.pack(">I", len(head) + len(body))
    answer = _exchange(server, b"GIOP\x01" + bytes((minor, 0, 0)) + size + head + body)
    assert answer is not None
    h, reply = answer
    assert giop.decode_reply(reply, h).status == ReplyStatus.NO_EXCEPTION
    stub = Miro.Example(server.reference(_KEY, Miro.Example._repo_id), invoker)
    assert stub.getData() == Miro.ExampleStructIDL(0.5, 1e10)


def test_a_big_endian_client_is_served(served: tuple[IIOPServer, IIOPInvoker]) -> None:
    head = struct.pack(">IBxxxhxxI", 1, 3, 0, len(_KEY)) + _KEY
    head += b"\0" * (-len(head) % 4) + struct.pack(">I", len(_SET_DATA)) + _SET_DATA
    head += b"\0" * (-len(head) % 4) + struct.pack(">I", 0)
    _set_data_by_hand(served, 2, head)


def test_locate_requests_and_unknown_objects(served: tuple[IIOPServer, IIOPInvoker]) -> None:
    server, invoker = served
    for key, status in (
        (b"robot/Example", giop.LocateStatus.OBJECT_HERE),
        (b"x", giop.LocateStatus.UNKNOWN_OBJECT),
    ):
        ref = server.reference(key, Miro.Example._repo_id)
        assert invoker.locate(ref) == status
    missing = Miro.Example(server.reference(b"nobody", Miro.Example._repo_id), invoker)
    with pytest.raises(OBJECT_NOT_EXIST) as e:
        missing.getData()
    assert e.value.completed == CompletionStatus.NO


def test_requests_the_servant_cannot_take(served: tuple[IIOPServer, IIOPInvoker]) -> None:
    server, invoker = served
    ref = server.reference(b"robot/Example", Miro.Example._repo_id)
    reply = invoker.invoke(ref, "noSuchOperation", b"\0\1\0\0")
    assert reply is not None and reply.repo_id == BAD_OPERATION._repo_id
    reply = invoker.invoke(ref, "setData", b"\0\1\0\0\0\0\0\0\1\2")  # two doubles? 2 bytes
    assert reply is not None and reply.repo_id == MARSHAL._repo_id


@pytest.mark.parametrize(
    "data",
    [
        b"HTTP/1.1 200 OK\r\n\r\n",
        b"GIOP\x09\x09\x01\x00\0\0\0\0",
        giop.encode_reply(2, 1, ReplyStatus.NO_EXCEPTION, b""),  # a client does not send these
        b"GIOP\x01\x02\x01\x00\xff\xff\xff\x7f",  # 2 GiB announced
        b"GIOP\x01\x02\x01\x00\x04\0\0\0abcd",  # a request header that ends at once
        b"GIOP\x01\x02\x01\x07\x04\0\0\0\x05\0\0\0",  # a fragment of nothing
    ],
)
def test_protocol_errors_get_message_error(
    served: tuple[IIOPServer, IIOPInvoker], data: bytes
) -> None:
    server, invoker = served
    answer = _exchange(server, data)
    assert answer is not None and answer[0].type == MsgType.MESSAGE_ERROR
    stub = Miro.Example(server.reference(b"robot/Example", Miro.Example._repo_id), invoker)
    assert stub.getData() == Miro.ExampleStructIDL(1.0, 2.0)  # and the server goes on


def test_the_giop_reader_fuzzed(served: tuple[IIOPServer, IIOPInvoker]) -> None:
    """Valid requests mutated at random (bytes flipped, cut, grown, sizes lied about): each is
    answered (a reply or MessageError) or dropped, and afterwards the server still serves."""
    server, invoker = served
    errors: list[Any] = []
    old_hook = threading.excepthook
    threading.excepthook = errors.append
    rng = random.Random(1806)
    seeds = [
        giop.encode_request(m, 9, True, b"robot/Example", op, body)
        for m in (0, 1, 2)
        for op, body in (("getData", b""), ("setData", struct.pack("<dd", 1, 2)))
    ]
    seeds.append(giop.encode_locate_request(2, 4, b"robot/Example"))
    for _ in range(150):
        data = bytearray(rng.choice(seeds))
        for _ in range(rng.randint(1, 4)):
            if not data:
                break
            what = rng.random()
            at = rng.randrange(len(data))
            if what < 0.5:
                data[at] = rng.randrange(256)
            elif what < 0.7:
                del data[at:]
            elif what < 0.85:
                data[at:at] = rng.randbytes(rng.randint(1, 16))
            elif len(data) >= 12:
                struct.pack_into("<I", data, 8, rng.choice([0, 1, len(data), 2**31, 2**32 - 1]))
        with socket.create_connection(("127.0.0.1", server.port), timeout=10) as s:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
            s.settimeout(5)
            while s.recv(65536):  # whatever comes back, until the server closes
                pass
    threading.excepthook = old_hook
    assert not errors, [e.exc_value for e in errors]
    stub = Miro.Example(server.reference(b"robot/Example", Miro.Example._repo_id), invoker)
    stub.setData(3.0, 4.0)
    assert stub.getData() == Miro.ExampleStructIDL(3.0, 4.0)


def test_the_decoders_fuzzed() -> None:
    """Every decoder, fed mutated input: a protocol error or MARSHAL, nothing else."""
    rng = random.Random(21)
    out = CdrOutput()
    write_typecode(out, typecode_for(Miro.ExampleGroupIDL))
    samples: list[tuple[Callable[[bytes], object], bytes]] = [
        (lambda d: giop.decode_request(d, giop.read_header(d)),
         giop.encode_request(1, 2, True, b"key", "op", b"12345678")),
        (lambda d: giop.decode_reply(d, giop.read_header(d)),
         giop.encode_reply(2, 2, ReplyStatus.USER_EXCEPTION, b"12345678")),
        (lambda d: IOR.from_string("IOR:" + d.hex()), bytes.fromhex(OMNINAMES_IOR[4:])),
        (lambda d: read_typecode(CdrInput(d)), bytes(out.buf)),
        (lambda d: read_any(CdrInput(d)), _any_bytes()),
    ]  # fmt: skip
    for decode, sample in samples:
        for _ in range(400):
            data = bytearray(sample)
            for _ in range(rng.randint(1, 3)):
                at = rng.randrange(len(data))
                if rng.random() < 0.7:
                    data[at] = rng.choice([0, 1, 0x7F, 0xFF, rng.randrange(256)])
                else:
                    del data[at:]
                if not data:
                    break
            with contextlib.suppress(giop.GiopError, UrlError, MARSHAL):
                decode(bytes(data))


def _any_bytes() -> bytes:
    out = CdrOutput()
    write_any(out, Miro.ExampleGroupIDL(1, [Miro.ExampleStructIDL(1, 2)]))
    return bytes(out.buf)


# ---- a client, met by hand-made servers ---------------------------------------------------------


class FakeServer:
    """A listening socket whose connections are answered by `script(connection)`."""

    def __init__(self, script: Callable[[socket.socket, int], None]) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.script = script
        self.connections = 0
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.connections += 1
            threading.Thread(target=self._serve, args=(conn, self.connections), daemon=True).start()

    def _serve(self, conn: socket.socket, n: int) -> None:
        with conn, contextlib.suppress(OSError, EOFError):
            self.script(conn, n)

    def stub(self, invoker: IIOPInvoker, timeout: float | None = None) -> Any:
        stub = Miro.Example(
            ref_from_ior(IOR.iiop(Miro.Example._repo_id, "127.0.0.1", self.port, b"k")), invoker
        )
        if timeout is not None:
            stub._timeout = timeout
        return stub

    def close(self) -> None:
        self.sock.close()


def _request(conn: socket.socket) -> tuple[giop.Header, giop.Request]:
    h, msg = GiopConnection(conn, "client").read_message()
    return h, giop.decode_request(msg, h)


def _be_reply(request_id: int, status: int, body: bytes) -> bytes:
    head = struct.pack(">III", request_id, status, 0)
    return b"GIOP\x01\x02\x00\x01" + struct.pack(">I", len(head) + len(body)) + head + body


@pytest.mark.parametrize("principal", range(8))
def test_a_giop_1_0_body_is_read_wherever_it_begins(
    served: tuple[IIOPServer, IIOPInvoker], principal: int
) -> None:
    """A GIOP 1.0 body follows the request header at once (here after a principal of 0 to 7
    octets), its values aligned to the message's start: decoded where it is, not forwarded."""
    head = struct.pack(">IIB", 0, 5, 1) + b"\0" * 3 + struct.pack(">I", len(_KEY)) + _KEY
    head += b"\0" * (-len(head) % 4) + struct.pack(">I", len(_SET_DATA)) + _SET_DATA
    head += b"\0" * (-len(head) % 4) + struct.pack(">I", principal) + b"p" * principal
    _set_data_by_hand(served, 0, head)


@pytest.fixture
def invoker() -> Iterator[IIOPInvoker]:
    inv = IIOPInvoker()
    yield inv
    inv.close()


def _serving(script: Callable[[socket.socket, int], None]) -> Iterator[FakeServer]:
    server = FakeServer(script)
    yield server
    server.close()


def test_big_endian_replies_and_exceptions(invoker: IIOPInvoker) -> None:
    def script(conn: socket.socket, n: int) -> None:
        _, req = _request(conn)
        conn.sendall(_be_reply(req.request_id, 0, struct.pack(">dd", 2.5, -1)))
        _, req = _request(conn)
        sysex = b"IDL:acme.com/Strange:1.0\0"
        body = (
            struct.pack(">I", len(sysex))
            + sysex
            + b"\0" * (-len(sysex) % 4)
            + struct.pack(">II", 17, 2)
        )
        conn.sendall(_be_reply(req.request_id, 2, body))
        _request(conn)

    for server in _serving(script):
        stub = server.stub(invoker)
        assert stub.getData() == Miro.ExampleStructIDL(2.5, -1.0)
        with pytest.raises(UNKNOWN, match=r"acme\.com/Strange") as e:
            stub.getData()
        assert (e.value.minor, e.value.completed) == (17, CompletionStatus.MAYBE)


def test_location_forward_is_followed_and_kept(
    served: tuple[IIOPServer, IIOPInvoker], invoker: IIOPInvoker
) -> None:
    real, _ = served

    def script(conn: socket.socket, n: int) -> None:
        while True:
            _, req = _request(conn)
            out = CdrOutput()
            real.ior(b"robot/Example", Miro.Example._repo_id).write(out)
            conn.sendall(
                giop.encode_reply(2, req.request_id, ReplyStatus.LOCATION_FORWARD, out.buf)
            )

    for server in _serving(script):
        stub = server.stub(invoker)
        assert stub.getData() == Miro.ExampleStructIDL(1.0, 2.0)
        assert stub.getData() == Miro.ExampleStructIDL(1.0, 2.0)
        assert server.connections == 1  # the second call went straight to where it was sent


def test_an_orderly_close_before_the_reply_is_retried(invoker: IIOPInvoker) -> None:
    def script(conn: socket.socket, n: int) -> None:
        _h, req = _request(conn)
        if n == 1:
            conn.sendall(giop.encode_simple(2, MsgType.CLOSE_CONNECTION))
            return
        conn.sendall(
            giop.encode_reply(2, req.request_id, ReplyStatus.NO_EXCEPTION, struct.pack("<dd", 7, 8))
        )
        _request(conn)

    for server in _serving(script):
        assert server.stub(invoker).getData() == Miro.ExampleStructIDL(7.0, 8.0)
        assert server.connections == 2


@pytest.mark.parametrize(
    ("answer", "error", "text"),
    [
        (b"\xff\0\0\0\0\0\0\0\x01\x7f\x03", TRANSIENT, "ZeroMQ peer"),
        (b"SSH-2.0-OpenSSH\r\n", TRANSIENT, "does not speak GIOP"),
        (giop.encode_simple(2, MsgType.MESSAGE_ERROR), COMM_FAILURE, "could not read our GIOP"),
        (b"GIOP\x01\x02\x01\x01\x04\0\0\0\x01\0\0\0", COMM_FAILURE, "malformed Reply header"),
        (b"", COMM_FAILURE, "lost the connection"),
    ],
)
def test_peers_that_go_wrong(
    invoker: IIOPInvoker, answer: bytes, error: type[Exception], text: str
) -> None:
    def script(conn: socket.socket, n: int) -> None:
        conn.recv(65536)
        conn.sendall(answer)

    for server in _serving(script):
        with pytest.raises(error, match=text):
            server.stub(invoker).getData()


def test_a_call_that_times_out_is_cancelled(invoker: IIOPInvoker) -> None:
    seen: list[MsgType] = []
    done = threading.Event()

    def script(conn: socket.socket, n: int) -> None:
        _request(conn)
        h, _ = GiopConnection(conn, "client").read_message()
        seen.append(h.type)
        done.set()

    for server in _serving(script):
        with pytest.raises(TIMEOUT) as e:
            server.stub(invoker, timeout=0.2).getData()
        assert e.value.completed == CompletionStatus.MAYBE
        assert done.wait(10) and seen == [MsgType.CANCEL_REQUEST]


def test_nothing_listening_is_transient_and_not_sent(invoker: IIOPInvoker) -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    stub = Miro.Example(
        ref_from_ior(IOR.iiop(Miro.Example._repo_id, "127.0.0.1", port, b"k")), invoker
    )
    with pytest.raises(TRANSIENT) as e:
        stub.getData()
    assert e.value.completed == CompletionStatus.NO


# ---- TypeCodes and anys ----------------------------------------------------------------------


def test_typecodes_of_generated_types_write_and_read_back() -> None:
    tc = typecode_for(Miro.ExampleGroupIDL)
    assert (tc.kind, tc.id, [n for n, _ in tc.members]) == (
        K.tk_struct,
        "IDL:Miro/ExampleGroupIDL:1.0",
        ["c", "PointList"],
    )
    out = CdrOutput(bytearray(b"\0\0\0"))  # an odd start: alignment counts from 0
    write_typecode(out, tc)
    back = read_typecode(CdrInput(bytes(out.buf), 3))
    assert back.equivalent(tc) and back.members[1][1].resolved().kind == K.tk_sequence


def test_recursive_typecodes_use_indirections() -> None:
    node = TypeCode(K.tk_struct, "IDL:T/Node:1.0", "Node")
    node.members = [
        ("value", TypeCode(K.tk_long)),
        ("children", TypeCode(K.tk_sequence, content=node)),
    ]
    out = CdrOutput()
    write_typecode(out, node)
    assert b"\xff\xff\xff\xff" in out.buf
    back = read_typecode(CdrInput(bytes(out.buf)))
    assert back.members[1][1].content is back
    value = {"value": 1, "children": [{"value": 2, "children": []}]}
    stream = CdrOutput(bytearray(b"\0"))
    write_any(stream, Any_(node, value))
    assert read_any(CdrInput(bytes(stream.buf), 1)) == value


@pytest.mark.parametrize("start", range(8))
def test_anys_of_generated_types_at_any_offset(start: int) -> None:
    value = Miro.ExampleGroupIDL(
        -3, [Miro.ExampleStructIDL(0.5, 1e300), Miro.ExampleStructIDL(2, 3)]
    )
    out = CdrOutput(bytearray(start))
    write_any(out, value)
    out.double(9.5)
    inp = CdrInput(bytes(out.buf), start)
    assert read_any(inp) == value
    assert inp.double() == 9.5


def test_transcoding_realigns_8_byte_members() -> None:
    tc = typecode_for(Miro.ExampleStructIDL)
    data = Miro.ExampleStructIDL(1.25, -7.5).serialize()
    moved = CdrOutput(bytearray(4))  # 4 bytes off a multiple of 8: the doubles move
    transcode(tc, CdrInput(data[4:]), moved, "miro", "giop")
    assert struct.unpack_from("<dd", moved.buf, 8) == (1.25, -7.5)
