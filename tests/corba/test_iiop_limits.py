"""The IIOP server's limits, met over real sockets: the byte budget (a request it has no room
for is answered TRANSIENT and the connection goes on), fragments counted per connection, the
connection cap (the connection heard from least recently makes room), connections silent
part-way through a message, and the rule that IIOP stays on loopback unless `--insecure`.

The floods with real server processes, their memory and CPU, are in test_attack_iiop.py."""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import Miro
import Miro__POA
import pytest
from giop_attacks import fragment, request
from loopback import eventually, free_port, service_env
from miro_cli import REPO

from miro_gen import TRANSIENT, CompletionStatus
from miro_gen.corba import IIOPInvoker, IIOPServer, giop
from miro_gen.corba.connection import GiopConnection
from miro_gen.corba.fragments import MAX_UNFINISHED
from miro_gen.corba.giop import MsgType, ReplyStatus
from miro_gen.corba.inbound import charge_of
from miro_gen.corba.server import BeyondLoopback
from miro_gen.runtime import rpc
from miro_gen.runtime.cdrstream import CdrInput

MIB = 1 << 20
KEY = b"robot/Example"


class ExampleImpl(Miro__POA.Example):
    def __init__(self) -> None:
        self.value = Miro.ExampleStructIDL(1.0, 2.0)

    def getData(self) -> Miro.ExampleStructIDL:
        return self.value

    def setData(self, a: float, b: float) -> None:
        self.value = Miro.ExampleStructIDL(a, b)


def serve(**limits: object) -> tuple[IIOPServer, IIOPInvoker]:
    invoker = IIOPInvoker()
    server = IIOPServer(invoker, **limits)  # type: ignore[arg-type]
    server.activate(ExampleImpl(), KEY)
    return server, invoker


@pytest.fixture
def small_budget() -> Iterator[tuple[IIOPServer, IIOPInvoker]]:
    """A server whose budget takes one 2 MiB request at a time (beside small ones)."""
    server, invoker = serve(budget=charge_of(2 * MIB) + 4 * MIB)
    yield server, invoker
    invoker.close()


def stub(server: IIOPServer, invoker: IIOPInvoker) -> Miro.Example:
    return Miro.Example(server.reference(KEY, Miro.Example._repo_id), invoker)


def set_data(request_id: int, a: float, b: float) -> bytes:
    """A whole GIOP 1.2 setData(a, b) request."""
    head = request(request_id, len(request(request_id)) - 12 + 16)
    return head + struct.pack("<dd", a, b)


def reply_to(conn: GiopConnection) -> tuple[int, str]:
    """(request id, "OK" or the repository id of the system exception) of the next reply."""
    h, msg = conn.read_message()
    assert h.type == MsgType.REPLY, h
    reply = giop.decode_reply(msg, h)
    if reply.status == ReplyStatus.NO_EXCEPTION:
        return reply.request_id, "OK"
    assert reply.status == ReplyStatus.SYSTEM_EXCEPTION
    inp = CdrInput(msg, reply.body, 0 if reply.little else 1)
    return reply.request_id, inp.string("repository id")


def connect(server: IIOPServer) -> tuple[socket.socket, GiopConnection]:
    s = socket.create_connection(("127.0.0.1", server.port), timeout=30)
    return s, GiopConnection(s, "server")


# ---- the byte budget ---------------------------------------------------------------------------


def test_a_request_the_budget_has_no_room_for_is_refused_and_the_connection_goes_on(
    small_budget: tuple[IIOPServer, IIOPInvoker],
) -> None:
    server, invoker = small_budget
    held, _ = connect(server)  # one large request held part-way: the large share is spent
    held.sendall(request(1, 2 * MIB - 64) + bytes(MIB))
    s, conn = connect(server)
    with s:
        s.sendall(request(7, 2 * MIB - 64) + bytes(2 * MIB - 64 - len(request(7)) + 12))
        assert reply_to(conn) == (7, TRANSIENT._repo_id)
        s.sendall(set_data(8, 5.0, 6.0))  # the same connection, a small request: served
        assert reply_to(conn) == (8, "OK")
    assert stub(server, invoker).getData() == Miro.ExampleStructIDL(5.0, 6.0)
    held.close()


def test_the_refusal_says_what_to_do(small_budget: tuple[IIOPServer, IIOPInvoker]) -> None:
    server, invoker = small_budget
    held, _ = connect(server)
    held.sendall(request(1, 2 * MIB - 64) + bytes(MIB))
    big = Miro.ExampleGroupIDL(1, [Miro.ExampleStructIDL(float(i), 0.0) for i in range(200_000)])
    group = invoker.invoke(
        server.reference(KEY, Miro.Example._repo_id), "setData", big.serialize()
    )  # 3.2 MB: more than is left of the budget for large requests
    assert group is not None and group.repo_id == TRANSIENT._repo_id
    with pytest.raises(TRANSIENT, match=r"too much in hand .* try again") as e:
        rpc.raise_system_exception(group)
    assert e.value.completed == CompletionStatus.NO
    held.close()


def test_the_budget_comes_back_when_connections_close(
    small_budget: tuple[IIOPServer, IIOPInvoker],
) -> None:
    server, _ = small_budget
    for n in range(5):  # each holds the whole large share until it is closed
        held, _ = connect(server)
        held.sendall(request(1, 2 * MIB - 64) + bytes(MIB))
        s, conn = connect(server)
        with s:
            s.sendall(set_data(2, float(n), 0.0))
            assert reply_to(conn) == (2, "OK")
        held.close()
    eventually(lambda: server.budget.used == 0)  # the server saw the last one go
    s, conn = connect(server)
    with s:  # a large request finds room once the holders are gone
        head = request(3, 16 + len(request(3)) - 12 + MIB)
        s.sendall(head + struct.pack("<dd", 9.0, 9.0) + bytes(MIB))
        assert reply_to(conn) == (3, "OK")


# ---- fragments ---------------------------------------------------------------------------------


def test_fragments_are_counted_per_connection() -> None:
    """A connection's unfinished fragmented messages may hold one message limit together:
    the request whose fragment would go beyond it is refused (its later fragments are thrown
    away), and more than MAX_UNFINISHED at once close the connection."""
    server, invoker = serve(max_message=2 * MIB)
    try:
        s, conn = connect(server)
        with s:
            for rid in (1, 2):
                s.sendall(request(rid, more=True) + fragment(rid, bytes(900_000), more=True))
            s.sendall(fragment(2, bytes(300_000), more=True))  # 2.1 MB unfinished: beyond
            assert reply_to(conn) == (2, TRANSIENT._repo_id)
            s.sendall(fragment(2, bytes(1000), more=False))  # thrown away, not an error
            s.sendall(fragment(1, struct.pack("<dd", 3.0, 4.0), more=False))  # fits still
            assert reply_to(conn) == (1, "OK")  # setData(0.0, 0.0): the body's first bytes
            for rid in range(10, 10 + MAX_UNFINISHED + 1):
                s.sendall(request(rid, more=True))
            h, _ = conn.read_message()
            assert h.type == MsgType.MESSAGE_ERROR
        assert stub(server, invoker).getData() == Miro.ExampleStructIDL(0.0, 0.0)
        eventually(lambda: server.budget.used == 0)  # what the closed connection held too
    finally:
        invoker.close()


# ---- connections -------------------------------------------------------------------------------


def test_the_connection_heard_from_least_recently_makes_room() -> None:
    server, invoker = serve(max_connections=4)
    try:
        first = [connect(server) for _ in range(4)]
        for s, _ in first[1:]:
            s.sendall(b"GIOP")  # part-way through a header: heard from, later than the first
        assert stub(server, invoker).getData() == Miro.ExampleStructIDL(1.0, 2.0)
        h, _ = first[0][1].read_message()  # the first made room, told in order
        assert h.type == MsgType.CLOSE_CONNECTION
        assert server.io.evicted >= 1 and server.io.connections <= 4
        for s, _ in first:
            s.close()
    finally:
        invoker.close()


def test_a_connection_silent_part_way_through_a_message_is_closed() -> None:
    server, invoker = serve(stall=0.3)
    try:
        s, _ = connect(server)
        with s:
            s.sendall(request(1, 1000))
            s.settimeout(30)
            assert s.recv(100) == b""  # closed (generous timeout: only to avoid a hang)
        eventually(lambda: server.budget.used == 0)
    finally:
        invoker.close()


# ---- loopback only, unless asked ---------------------------------------------------------------


def test_iiop_beyond_loopback_is_refused_unless_asked() -> None:
    invoker = IIOPInvoker()
    with pytest.raises(BeyondLoopback, match=r"IIOP on 0\.0\.0\.0:\d+ would be served beyond"):
        IIOPServer(invoker, "0.0.0.0", 0)
    server = IIOPServer(invoker, "0.0.0.0", 0, "127.0.0.1", beyond_loopback=True)
    server.activate(ExampleImpl(), KEY)
    assert stub(server, invoker).getData() == Miro.ExampleStructIDL(1.0, 2.0)
    invoker.close()


def _example_a(*options: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(REPO / "services" / "exampleA.py"), *options],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )


@pytest.mark.parametrize("keyed", [False, True], ids=["without a key", "with the fleet key"])
def test_a_server_asked_for_iiop_on_every_interface_stops_and_says_why(
    naming: str, keyed: bool, tmp_path: Path
) -> None:
    """With or without a key (which covers ZeroMQ only), --iiop-endpoint beyond loopback needs
    --insecure: the server stops at start-up with one line that says what is refused and how
    to allow it, and nothing listens."""
    env = service_env(HOME=str(tmp_path))
    if keyed:
        made = subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", "keys", "new", str(tmp_path / "fleet")],
            capture_output=True, text=True, env=env, timeout=60,
        )  # fmt: skip
        assert made.returncode == 0, made.stderr
        env["MIRO_KEYS"] = str(tmp_path / "fleet.key_secret")
    port = free_port()
    done = _example_a(
        "--naming", naming, "-MNC", "robot1", "--iiop-endpoint", f"0.0.0.0:{port}", env=env
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert f"IIOP on 0.0.0.0:{port} would be open to other machines, in the clear" in lines[0]
    assert "--insecure" in lines[0] and "--iiop-endpoint 127.0.0.1:PORT" in lines[0]
    with pytest.raises(OSError):  # nothing listens there
        socket.create_connection(("127.0.0.1", port), timeout=5).close()
