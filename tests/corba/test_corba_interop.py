"""miro-gen and C++ omniORB peers, across IIOP, through Debian's omniNames.

The C++ peer (tests/corba/peer.cc) is compiled once with omniidl and g++; omniNames runs on a
free port for the whole module. Checked both ways: every IDL type kind of tests/corba/Peer.idl,
every parameter mode, user exceptions (with members realigned after their repository id),
system exceptions with their minor codes and completion status, one-way calls, attributes,
object references as arguments and results (a callback into the caller), names bound by one
side and resolved by the other as Miro lays them out, GIOP 1.0 and 1.1 peers, restarted
servers reached through the references their clients hold, and a naming URL that the process
tells apart (ZeroMQ or GIOP).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from array import array
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import zmq
from corba_peers import (
    CppPeer,
    OmniNames,
    echo_servant,
    missing_tools,
    readline,
    run_peer,
    wait_giop,
)
from loopback import NamingProcess, free_port, service_env
from miro_cli import REPO
from repo_paths import TESTS

from miro_gen import BAD_PARAM, TRANSIENT, UNKNOWN, Client, CompletionStatus, Server
from miro_gen.corba import CORBA_SYSTEM_EXCEPTIONS, IIOPInvoker, NamingContext
from miro_gen.corba.naming import Peer as PeerKind
from miro_gen.corba.naming import probe

pytestmark = [
    pytest.mark.skipif(bool(missing_tools()), reason=f"needs {', '.join(missing_tools())}"),
    pytest.mark.timeout(300),
]


class ServerThread:
    """A miro-gen Server whose reactor runs in a thread of the test."""

    def __init__(self, *args: str) -> None:
        self.server = Server(["test", *args], context=zmq.Context())
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def start(self) -> ServerThread:
        self.thread.start()
        return self

    def stop(self) -> None:
        self.server.shutdown()
        self.thread.join(10)
        assert not self.thread.is_alive()


def exercise(echo: Any, peer_gen: SimpleNamespace, cpp: bool) -> None:
    """Call every operation of a Peer::Echo and check what comes back."""
    P = peer_gen.Peer
    prims = P.Prims(
        -32768, 65535, -(2**31), 2**32 - 1, -(2**63), 2**64 - 1, 1.5, -2.25, True, "z", 255
    )
    assert echo.echo_prims(prims) == prims
    # Sequences and arrays of numbers arrive as array.array (DESIGN.md): built so here too.
    matrix_in = [array("i", [0, 1, 2]), array("i", [3, 4, 5])]
    nested = P.Nested(
        "nested", P.Point(1, -1), [P.Point(1, 2), P.Point(3, 4)], P.Shape(value=0.5),
        P.Color.BLUE, matrix_in, array("i", [-1, 0, 2**31 - 1]), [P.Color.GREEN, P.Color.RED],
        [True, False, True], "tag", 1e300,
    )  # fmt: skip
    assert echo.echo_nested(nested) == nested
    many = [
        nested,
        P.Nested(outline=P.Shape(name="circle")),
        P.Nested(outline=P.Shape(99, P.Point(7, 8))),
    ]
    assert echo.echo_nesteds(many) == many
    assert echo.echo_text("héllo, wörld") == "héllo, wörld"
    assert echo.echo_text("") == ""
    assert list(echo.echo_longs(list(range(-500, 500)))) == list(range(-500, 500))
    assert list(echo.echo_doubles([i / 3 for i in range(5)])) == [i / 3 for i in range(5)]
    assert echo.echo_octets(bytes(range(256))) == bytes(range(256))
    assert echo.echo_strings(["a", "", "ccc"]) == ["a", "", "ccc"]
    for shape in (
        P.Shape(count=5),
        P.Shape(3, 1.25),
        P.Shape(name="x"),
        P.Shape(99, P.Point(9, 8)),
    ):
        assert echo.echo_shape(shape) == shape
    assert echo.echo_pick(P.Pick(g=P.Point(1, 2))) == P.Pick(g=P.Point(1, 2))
    assert echo.echo_pick(P.Pick(P.Color.BLUE, None)) == P.Pick(P.Color.BLUE, None)
    assert echo.echo_color(P.Color.GREEN) == P.Color.GREEN
    result, twice, text, moved, matrix = echo.mixed(6, P.Point(1, 2), [[1, 2, 3], [4, 5, 6]])
    assert (result, twice, text, moved) == (1.5, 12, "a=6", P.Point(2, 3))
    assert [list(row) for row in matrix] == [[10, 20, 30], [40, 50, 60]]
    echo.nothing()

    with pytest.raises(P.Failed) as failed:
        echo.raise_it(0)
    assert (failed.value.reason, failed.value.code, failed.value.when) == ("bad", 42, 2.5)
    with pytest.raises(P.Empty):
        echo.raise_it(1)
    with pytest.raises(BAD_PARAM) as bad:
        echo.raise_it(2)
    assert (bad.value.minor, bad.value.completed) == (7, CompletionStatus.NO)
    with pytest.raises(CORBA_SYSTEM_EXCEPTIONS["NO_PERMISSION"]) as denied:
        echo.raise_it(3)
    assert (denied.value.minor, denied.value.completed) == (5, CompletionStatus.YES)
    if not cpp:
        with pytest.raises(UNKNOWN):
            echo.raise_it(4)

    before = echo.fired()
    echo.fire(3)
    echo.fire(4)
    deadline = time.monotonic() + 10
    while echo.fired() != before + 7:
        assert time.monotonic() < deadline, "the one-way calls did not arrive"
        time.sleep(0.01)

    again = echo.myself()
    assert again.echo_text("again") == "again"
    assert echo.echo_object(None) is None
    assert echo.echo_object(echo)._ref.key == echo._ref.key

    class Callback(peer_gen.POA.Callback):  # type: ignore[misc, name-defined]
        def notify(self, what: str) -> str:
            return f"python got {what}"

    assert echo.call_back(Callback(), "ping") == "python got ping"
    mine = Callback()
    back = echo.echo_callbacks([mine, None, mine])
    assert back[1] is None and back[0] == back[2]
    assert (
        back[0].notify("through C++" if cpp else "back")
        == f"python got {'through C++' if cpp else 'back'}"
    )
    assert echo.swap_echo(again).echo_text("swapped") == "swapped"
    echo._set_counter(41)
    assert echo._get_counter() == 41
    assert echo._get_label() == ("cpp" if cpp else "python")


# ---- Python calls C++ ----------------------------------------------------------------------


def test_a_python_client_calls_a_cpp_server_bound_in_omninames(
    peer_bin: Path, omninames: OmniNames, peer_gen: SimpleNamespace
) -> None:
    cpp = CppPeer(peer_bin, "server", "robot1/EchoCpp", naming=omninames.url)
    try:
        cpp.ready()
        client = Client(
            ["test", "--naming", omninames.url, "-MNC", "robot1"], context=zmq.Context()
        )
        try:
            echo = client.resolve_name(
                "EchoCpp", peer_gen.Peer.Echo
            )  # robot1/EchoCpp, context first
            exercise(echo, peer_gen, cpp=True)
        finally:
            client.close()
    finally:
        cpp.kill()


def test_a_giop_1_0_cpp_server(peer_bin: Path, peer_gen: SimpleNamespace) -> None:
    """Its IOR says IIOP 1.0: requests go as GIOP 1.0, bodies aligned by a padding context."""
    cpp = CppPeer(peer_bin, "server", "-", "-ORBmaxGIOPVersion", "1.0")
    try:
        ior = cpp.ready()
        invoker = IIOPInvoker()
        try:
            echo = invoker.stub(peer_gen.Peer.Echo, ior)
            assert invoker._target(echo._ref).minor == 0
            exercise(echo, peer_gen, cpp=True)
        finally:
            invoker.close()
    finally:
        cpp.kill()


def test_a_restarted_cpp_server_is_called_through_the_stub_already_held(
    peer_bin: Path, peer_gen: SimpleNamespace
) -> None:
    port = free_port()
    endpoint = ("-ORBendPoint", f"giop:tcp:127.0.0.1:{port}")
    cpp = CppPeer(peer_bin, "server", "-", *endpoint)
    invoker = IIOPInvoker()
    try:
        echo = invoker.stub(peer_gen.Peer.Echo, cpp.ready())
        echo._set_counter(5)
        assert echo._get_counter() == 5
        cpp.kill()
        with pytest.raises((TRANSIENT, CORBA_SYSTEM_EXCEPTIONS["COMM_FAILURE"])):
            echo.nothing()
        cpp = CppPeer(peer_bin, "server", "-", *endpoint)
        cpp.ready()
        assert echo._get_counter() == 0  # a new process, the same persistent reference
        assert echo.echo_text("back") == "back"
    finally:
        invoker.close()
        cpp.kill()


# ---- C++ calls Python -------------------------------------------------------------------------


def test_a_cpp_client_calls_a_python_server_bound_in_omninames(
    peer_bin: Path, omninames: OmniNames, peer_gen: SimpleNamespace
) -> None:
    server = ServerThread("--naming", omninames.url, "-MNC", "robot2")
    server.server.add_to_name_service(echo_servant(peer_gen.Peer, peer_gen.POA), "EchoPy")
    server.start()
    try:
        status, out = run_peer(peer_bin, "client", "robot2/EchoPy", naming=omninames.url)
        assert status == 0 and "ALL PASSED" in out, out
        # Laid out as Miro's C++ Server does: a context robot2 under the root, EchoPy in it.
        invoker = IIOPInvoker()
        root = NamingContext(server.server.corba.naming.root.ref, invoker)
        bindings = {tuple(b.name): b.is_context for b in root.list()}
        assert bindings[(("robot2", ""),)] is True
        inner = root.context([("robot2", "")]).list()
        assert [(b.name, b.is_context) for b in inner] == [([("EchoPy", "")], False)]
        invoker.close()
    finally:
        server.stop()
    # ... and unbound when the server stops.
    status, out = run_peer(peer_bin, "client", "robot2/EchoPy", naming=omninames.url)
    assert status != 0 and "NotFound" in out


@pytest.mark.parametrize("version", ["1.0", "1.1"])
def test_giop_1_0_and_1_1_clients_are_served(
    peer_bin: Path, omninames: OmniNames, peer_gen: SimpleNamespace, version: str
) -> None:
    """Their request bodies may start 4 bytes off a multiple of 8 (the body follows the
    request header at once): they are decoded where they are, one-way requests too, and the
    reference is the one omniORB resolved (`_is_equivalent` to itself)."""
    server = ServerThread("--naming", omninames.url, "-MNC", f"old{version[-1]}")
    server.server.add_to_name_service(echo_servant(peer_gen.Peer, peer_gen.POA), "Echo")
    server.start()
    try:
        status, out = run_peer(
            peer_bin, "client", f"old{version[-1]}/Echo", "-ORBmaxGIOPVersion", version,
            naming=omninames.url,
        )  # fmt: skip
        assert status == 0 and "ALL PASSED" in out, out
    finally:
        server.stop()


def test_a_restarted_python_server_keeps_its_iors(
    peer_bin: Path, omninames: OmniNames, peer_gen: SimpleNamespace, tmp_path: Path
) -> None:
    """--iiop-endpoint with a fixed port: the same IOR reaches the restarted server."""
    port = free_port()
    script = tmp_path / "echo_server.py"
    script.write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(peer_gen.path)!r})\n"
        "import Peer, Peer__POA\n"
        "from corba_peers import echo_servant\n"
        "from miro_gen import Server\n"
        "server = Server(sys.argv)\n"
        "server.add_to_name_service(echo_servant(Peer, Peer__POA), 'Echo')\n"
        "print('READY', flush=True)\n"
        "server.run()\n"
    )
    env = service_env()
    env["PYTHONPATH"] += f":{TESTS}"
    args = [sys.executable, str(script), "--naming", omninames.url, "-MNC", "restart",
            "--iiop-endpoint", f"127.0.0.1:{port}"]  # fmt: skip

    def start() -> subprocess.Popen[str]:
        proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True, env=env)
        assert proc.stdout is not None and proc.stdout.readline().strip() == "READY"
        return proc

    proc = start()
    client = Client(["test", "--naming", omninames.url], context=zmq.Context())
    try:
        echo = client.resolve_name("restart/Echo", peer_gen.Peer.Echo)
        assert f"127.0.0.1:{port}" in echo._ref.endpoint
        echo._set_counter(3)
        proc.kill()
        proc.wait(10)
        proc = start()
        assert echo._get_counter() == 0
        assert echo.echo_text("same IOR") == "same IOR"
    finally:
        client.close()
        proc.kill()
        proc.wait(10)


def test_python_to_python_over_iiop(omninames: OmniNames, peer_gen: SimpleNamespace) -> None:
    """Both ends miro-gen, through omniNames: the same checks as against C++."""
    server = ServerThread("--naming", omninames.url, "-MNC", "robot3")
    server.server.add_to_name_service(echo_servant(peer_gen.Peer, peer_gen.POA), "Echo")
    server.start()
    client = Client(["test", "--naming", omninames.url, "-MNC", "robot3"], context=zmq.Context())
    try:
        exercise(client.resolve_name("Echo", peer_gen.Peer.Echo), peer_gen, cpp=False)
    finally:
        client.close()
        server.stop()


# ---- which naming service -------------------------------------------------------------------


def test_the_manual_iioploc_url_still_reaches_miro_naming(peer_gen: SimpleNamespace) -> None:
    """`-ORBInitRef NameService=iioploc://HOST:PORT/NameService` (the manual's spelling) with
    `miro naming` there: the process hears ZeroMQ's greeting and uses the ZeroMQ naming."""
    naming = NamingProcess()
    try:
        assert probe("127.0.0.1", naming.port) == PeerKind.ZMQ
        url = f"NameService=iioploc://127.0.0.1:{naming.port}/NameService"
        server = ServerThread("-ORBInitRef", url, "-MNC", "manual")
        assert server.server.corba is None
        server.server.add_to_name_service(echo_servant(peer_gen.Peer, peer_gen.POA), "Echo")
        server.start()
        client = Client(["test", "-ORBInitRef", url], context=zmq.Context())
        try:
            echo = client.resolve_name("manual/Echo", peer_gen.Peer.Echo)
            assert echo._ref.endpoint.startswith("tcp://")
            assert echo.echo_text("over ZeroMQ") == "over ZeroMQ"
        finally:
            client.close()
            server.stop()
    finally:
        naming.stop()


def test_a_zeromq_peer_where_giop_is_expected_is_named(peer_gen: SimpleNamespace) -> None:
    naming = NamingProcess()
    invoker = IIOPInvoker()
    try:
        echo = invoker.stub(peer_gen.Peer.Echo, f"corbaloc:iiop:127.0.0.1:{naming.port}/Echo")
        with pytest.raises(TRANSIENT, match=r"ZeroMQ peer.*--naming tcp://127.0.0.1:\d+") as e:
            echo.nothing()
        assert e.value.completed == CompletionStatus.NO
    finally:
        invoker.close()
        naming.stop()


def test_a_giop_peer_where_zeromq_is_expected_is_named(omninames: OmniNames) -> None:
    client = Client(
        ["test", "--naming", f"tcp://127.0.0.1:{omninames.port}"], context=zmq.Context()
    )
    try:
        with pytest.raises(TRANSIENT, match=r"CORBA naming service.*corbaloc") as e:
            client.resolve_name("anything", __import__("MiroNaming").Registry)
        assert "corbaloc" in str(e.value)
    finally:
        client.close()


def test_giop_is_told_apart_from_nothing(omninames: OmniNames) -> None:
    assert probe("127.0.0.1", omninames.port) == PeerKind.GIOP
    assert probe("127.0.0.1", free_port(), timeout=0.2) == PeerKind.NONE
    wait_giop("127.0.0.1", omninames.port)


# ---- the manual's examples, unchanged, in a CORBA robot ----------------------------------------


def test_the_manuals_examples_run_against_omninames(omninames: OmniNames) -> None:
    """ExampleA to D started as the manual starts them, with -ORBInitRef naming omniNames:
    ExampleA is served over IIOP and bound in omniNames, ExampleB finds and polls it, ExampleC's
    event channel (ZeroMQ) is bound there too and ExampleD receives its events; `miro nslist`
    lists them from omniNames."""
    services = REPO / "services"
    nsc = ["-ORBInitRef", f"NameService={omninames.url}", "-MNC", "manualbot"]
    env = service_env()
    started: list[subprocess.Popen[str]] = []

    def start(script: str, *args: str) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [sys.executable, str(services / script), *nsc, *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        started.append(proc)
        return proc

    try:
        a = start("exampleA.py")
        assert readline(a.stdout, 30, "ExampleA") == "ExampleA is ready"
        b = subprocess.run(
            [sys.executable, str(services / "exampleB.py"), *nsc, "--count", "2", "--period", "0"],
            capture_output=True, text=True, env=env, timeout=60,
        )  # fmt: skip
        assert b.returncode == 0, b.stderr
        assert "Retrieved variables a and b are: 1 and 11" in b.stdout
        c = start("exampleC.py", "0.1")
        assert readline(c.stdout, 30, "ExampleC").startswith("ExampleC publishes")
        d = start("exampleD.py")
        assert readline(d.stdout, 30, "ExampleD").startswith("ExampleD listens")
        assert readline(d.stdout, 30, "ExampleD").startswith("Received ExampleEvent #")
        listed = subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", "nslist", "--naming", omninames.url,
             "manualbot"],
            capture_output=True, text=True, env=env, timeout=60,
        )  # fmt: skip
        assert listed.returncode == 0, listed.stderr
        assert "ExampleA  (IDL:Miro/Example:1.0 at iiop://" in listed.stdout
        assert "ExampleEventChannel  (" in listed.stdout
    finally:
        for proc in started:
            proc.send_signal(signal.SIGINT)
        for proc in started:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
