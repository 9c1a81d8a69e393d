"""ipc:// twins of tcp:// endpoints (miro_gen.transport.local): taken by peers on the same host,
and only there."""

from __future__ import annotations

import contextlib
import os
import sys

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
