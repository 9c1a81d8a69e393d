"""ipc:// twins of tcp:// endpoints (miro_gen.transport.local): taken by peers on the same host,
and only there."""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import time
from pathlib import Path

import pytest
import zmq

from miro_gen.transport import local

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux only")


def test_a_bound_twin_is_where_local_peers_connect() -> None:
    ctx = zmq.Context()
    sock = ctx.socket(zmq.PULL)
    try:
        while True:  # a port without a twin left behind by a process killed on it (in the
            # shared folder of this user: other tests', other jobs' on this host)
            port = sock.bind_to_random_port("tcp://127.0.0.1")
            endpoint = f"tcp://127.0.0.1:{port}"
            if not os.path.exists((local.ipc_twin(endpoint) or "ipc://")[len("ipc://") :]):
                break
            sock.unbind(endpoint)
        assert local.nearest(endpoint) == endpoint  # no twin yet
        twin = local.bind_twin(sock, endpoint)
        assert twin is not None and twin == local.ipc_twin(endpoint)
        assert local.nearest(endpoint) == twin
        folder = os.path.dirname(twin[len("ipc://") :])
        assert os.stat(folder).st_mode & 0o777 == 0o700
        push = ctx.socket(zmq.PUSH)
        push.connect(twin)
        push.send(b"through the twin")
        assert sock.poll(5000) and sock.recv() == b"through the twin"
        push.close(0)
    finally:
        sock.close(0)
        ctx.term()


def test_a_twin_left_by_a_killed_process_is_not_taken() -> None:
    """A process killed without closing leaves its socket file; a later peer of the same port
    must keep to TCP, where the port's new owner (or nobody) answers, not wait on a dead file."""
    import socket as sockets

    ctx = zmq.Context()
    sock = ctx.socket(zmq.PULL)
    try:
        port = sock.bind_to_random_port("tcp://127.0.0.1")
        endpoint = f"tcp://127.0.0.1:{port}"
        path = (local.ipc_twin(endpoint) or "ipc://").removeprefix("ipc://")
        dead = sockets.socket(sockets.AF_UNIX, sockets.SOCK_STREAM)
        dead.bind(path)  # bound, never listening, then gone: as a killed process leaves it
        dead.close()
        assert os.path.exists(path)
        assert local.nearest(endpoint) == endpoint
        push = ctx.socket(zmq.PUSH)
        push.connect(local.nearest(endpoint))
        push.send(b"over TCP")
        assert sock.poll(5000) and sock.recv() == b"over TCP"
        push.close(0)
    finally:
        sock.close(0)
        ctx.term()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)


def test_other_hosts_and_other_kinds_keep_their_endpoint(tmp_path: object) -> None:
    remote = "tcp://192.0.2.7:5555"  # TEST-NET-1: never an address of this host
    path = (local.ipc_twin(remote) or "ipc://").removeprefix("ipc://")
    open(path, "w").close()  # even with a file where its twin would be
    try:
        assert local.nearest(remote) == remote
    finally:
        os.unlink(path)
    for endpoint in ("ipc:///tmp/x", "inproc://x", "tcp://[::1]:notaport"):
        assert local.nearest(endpoint) == endpoint
    assert local.ipc_twin("inproc://x") is None


def test_socket_files_nobody_listens_on_are_removed_when_a_process_starts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The folder of a user whose processes were killed: the first use of the folder by a new
    process removes their socket files; a live one, one just bound (maybe not listening yet)
    and other files stay."""
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    folder = tmp_path / f"miro-{os.getuid()}"
    folder.mkdir(mode=0o700)
    long_ago = time.time() - 3600

    def socket_file(name: str, listen: bool, age: float | None = long_ago) -> socket.socket:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.bind(str(folder / name))
        if listen:
            s.listen()
        else:
            s.close()  # as a killed process leaves it: the file, nobody behind it
        if age is not None:
            os.utime(folder / name, (age, age))
        return s

    dead = [f"0-127.0.0.1-{port}" for port in range(40000, 40150)]  # 150 killed processes
    for name in dead:
        socket_file(name, listen=False)
    live = socket_file("0-127.0.0.1-2809", listen=True)
    socket_file("0-127.0.0.1-1", listen=False, age=None)  # bound a moment ago
    (folder / "notes.txt").write_text("not a socket")
    local._folder.cache_clear()
    try:
        assert local.ipc_twin("tcp://127.0.0.1:5") is not None
    finally:
        local._folder.cache_clear()  # the other tests' folder is the real one
        live.close()
    left = sorted(p.name for p in folder.iterdir())
    assert left == ["0-127.0.0.1-1", "0-127.0.0.1-2809", "notes.txt"]


def test_sweeping_looks_at_a_bounded_number_of_files(tmp_path: Path) -> None:
    for port in range(30):
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.bind(str(tmp_path / f"0-127.0.0.1-{port}"))
        s.close()
        os.utime(tmp_path / f"0-127.0.0.1-{port}", (0, 0))
    assert local.sweep(str(tmp_path), limit=10) == 10
    assert local.sweep(str(tmp_path), limit=100) == 20
    assert not list(tmp_path.iterdir())
