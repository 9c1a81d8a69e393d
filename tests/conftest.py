"""The checkout's generated code comes first on the path, including what the wheel leaves out
(the manual's example parameters, package Test). Multicast DNS is off for every test and every
process a test starts (MIRO_DISCOVERY=0: no naming service announced, none looked for), so that
nothing leaves loopback; the network namespaces of tests/transport/test_multihost.py turn it on
again for the processes inside them."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zmq

GENERATED = str(Path(__file__).resolve().parents[1] / "generated")
if GENERATED not in sys.path:
    sys.path.insert(0, GENERATED)
os.environ["MIRO_DISCOVERY"] = "0"


@pytest.fixture(scope="session", autouse=True)
def _session_state(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The naming services the tests start (themselves, or through `miro launch`) keep their
    logs of owners in a folder of this session's ($XDG_STATE_HOME), not in the user's."""
    old = os.environ.get("XDG_STATE_HOME")
    os.environ["XDG_STATE_HOME"] = str(tmp_path_factory.mktemp("state"))
    yield
    if old is None:
        os.environ.pop("XDG_STATE_HOME", None)
    else:
        os.environ["XDG_STATE_HOME"] = old


@pytest.fixture(scope="module")
def naming() -> Iterator[str]:
    """The endpoint of a `miro naming` process shared by a test module."""
    from loopback import NamingProcess

    process = NamingProcess()
    yield process.endpoint
    process.stop()


@pytest.fixture
def servers(naming: str) -> Iterator[Callable[[str], Any]]:
    """Makes Servers (`servers(naming_context)`) whose reactors run in threads of the test;
    stopped after it."""
    from loopback import RunningServer

    started: list[RunningServer] = []

    def make(context: str) -> Any:
        r = RunningServer(naming, context)
        started.append(r)
        return r.server

    yield make
    for r in reversed(started):
        r.stop()


@pytest.fixture
def reactor() -> Iterator[object]:
    """A Reactor running in a thread of its own; closed, with its context, after the test."""
    from miro_gen.transport.reactor import Reactor

    r = Reactor(zmq.Context())
    thread = r.run_in_thread()
    yield r
    r.stop()
    thread.join(5)
    assert not thread.is_alive(), "the reactor did not stop"
    r.close()
    r.context.term()


# ---- the CORBA tests' peers (tests/corba_peers.py) ----------------------------------------------


@pytest.fixture(scope="module")
def peer_bin() -> object:
    """The C++ omniORB peer, built once (and cached by the hash of its sources)."""
    from corba_peers import build_peer

    return build_peer()


@pytest.fixture(scope="module")
def omninames() -> Iterator[object]:
    """omniNames on a free port, for a test module."""
    from corba_peers import running_omninames

    with running_omninames() as names:
        yield names


@pytest.fixture(scope="module")
def peer_gen(tmp_path_factory: pytest.TempPathFactory) -> Iterator[object]:
    """The Python types of tests/corba/Peer.idl, generated and imported for a test module."""
    from corba_peers import peer_types

    with peer_types(tmp_path_factory.mktemp("peer_generated")) as types:
        yield types


# ---- the ROS 2 peer (tests/ros2_env.py) ------------------------------------------------------


@pytest.fixture(scope="session")
def ros2() -> object:
    """The ROS 2 environment of tests/ros2_env.py (its python, `share/` folder and process
    environment), made if it is not there; the test is skipped, saying why, if it cannot be."""
    from ros2_env import available

    env, reason = available()
    if env is None:
        pytest.skip(reason or "no ROS 2 environment")
    return env
