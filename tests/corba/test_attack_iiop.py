"""An IIOP server attacked as issue 33 found it could be, with real processes: beyond loopback
(network namespaces this test makes) a key-less IIOP client finds nothing unless the server
was started with --insecure, and then omniORB's C++ client is served (and a CORBA naming
service on another machine is talked to only with --insecure); on loopback, floods of
large requests held part-way, of unfinished fragments, of idle connections and of connections
beyond the process's descriptors stay within a stated memory bound, start no thread per
connection, do not make the accept loop spin, and legitimate calls are answered meanwhile.

The bound: the server's byte budget (`DEFAULT_BUDGET`, 160 MiB, which reserves twice a
message's size) over what the process had when it started serving. Before these limits, the
same floods added 561 MiB and 526 MiB (bench/bench_iiop_floods.py)."""

from __future__ import annotations

import resource
import socket
import subprocess
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import giop_attacks as attack
import pytest
from corba_peers import missing_tools
from loopback import service_env
from miro_cli import REPO
from netns import Hosts, network

from miro_gen.corba.server import DEFAULT_BUDGET, DEFAULT_WORKERS

MIB = 1 << 20
BOUND_MIB = DEFAULT_BUDGET / MIB
CALLS = 3  # pairs of legitimate calls made while a flood is held


@pytest.fixture
def victim(tmp_path: Path) -> Iterator[attack.Victim]:
    v = attack.Victim(REPO, log=tmp_path / "victim.err")
    yield v
    v.stop()


def needs_descriptors(n: int) -> None:
    """Skip when this process may not open `n` sockets (its hard limit)."""
    if resource.getrlimit(resource.RLIMIT_NOFILE)[1] < n + 256:
        pytest.skip(f"opening {n} connections needs a descriptor limit above {n + 256}")


def answered(v: attack.Victim) -> None:
    ok, failures = attack.calls_answered(v.port, CALLS)
    assert ok == CALLS, failures


# ---- memory ------------------------------------------------------------------------------------


def test_large_requests_held_part_way_stay_within_the_budget(victim: attack.Victim) -> None:
    """8 connections each send a 63 MiB request but its last byte (before: 561 MiB)."""
    held: list[socket.socket] = []
    try:
        held = attack.hold_big_requests(victim.port, 8, 63 * MIB)
        answered(victim)
        assert victim.added_mib() < BOUND_MIB
    finally:
        attack.close_all(held)


@pytest.mark.parametrize(("connections", "requests"), [(1, 32), (6, 4)])
def test_unfinished_fragments_stay_within_the_budget(
    victim: attack.Victim, connections: int, requests: int
) -> None:
    """Connections that each send fragmented 16 MiB requests and never their last fragment:
    32 on one (before: 526 MiB; a connection is closed at 8 unfinished), or 4 on each of 6
    (64 MiB each: their connection's limit, 384 MiB in all without the budget)."""
    held: list[socket.socket] = []
    try:
        held += [attack.hold_fragments(victim.port, requests, 16 * MIB) for _ in range(connections)]
        answered(victim)
        assert victim.added_mib() < BOUND_MIB
    finally:
        attack.close_all(held)


# ---- connections -------------------------------------------------------------------------------


def test_idle_connections_start_no_threads(victim: attack.Victim) -> None:
    """1,100 connections that send nothing (before: 1,102 threads): the server's one loop
    thread holds them, at most its connection cap of them (the least recently heard from make
    room), and callers get in."""
    needs_descriptors(1100)
    held: list[socket.socket] = []
    try:
        held = attack.open_idle(victim.port, 1100)
        descriptors = attack.settle(victim.pid)
        assert attack.status(victim.pid, "Threads") <= 3  # main, the loop (and slack for one)
        assert descriptors < 256 + 32  # the cap, and the process's own files
        answered(victim)
        assert attack.status(victim.pid, "Threads") <= 3 + DEFAULT_WORKERS
    finally:
        attack.close_all(held)


def test_out_of_descriptors_the_server_makes_room_instead_of_spinning(tmp_path: Path) -> None:
    """A process with 16 descriptors left, 1,100 connections: `accept` fails with EMFILE,
    the connections heard from least recently are closed to make room, the loop does not spin
    (before: it used all the CPU it could get, and no call got through)."""
    needs_descriptors(1100)
    log = tmp_path / "victim.err"
    v = attack.Victim(REPO, nofile=256, spare=16, log=log)
    held: list[socket.socket] = []
    try:
        held = attack.open_idle(v.port, 1100)
        attack.settle(v.pid)
        with attack.cpu_share(v.pid) as share:
            time.sleep(3)
        assert share[0] < 0.2, f"{share[0]:.0%} of a CPU with the flood held"
        answered(v)
        assert "no file descriptor left" in log.read_text()
    finally:
        attack.close_all(held)
        v.stop()


def test_out_of_descriptors_with_nothing_to_close_accepting_pauses(tmp_path: Path) -> None:
    """No descriptor left at all, nothing to close: accepting pauses (50 ms, doubling up to
    1 s) instead of asking again at once."""
    log = tmp_path / "victim.err"
    v = attack.Victim(REPO, nofile=256, spare=0, log=log)
    held: list[socket.socket] = []
    try:
        held = attack.open_idle(v.port, 200, seconds=5)
        time.sleep(1)
        with attack.cpu_share(v.pid) as share:
            time.sleep(3)
        assert share[0] < 0.2, f"{share[0]:.0%} of a CPU with the flood held"
        assert "cannot accept connections (Too many open files)" in log.read_text()
        assert "pausing" in log.read_text()
    finally:
        attack.close_all(held)
        v.stop()


# ---- beyond loopback ---------------------------------------------------------------------------

LAN = {"nsbox": "10.78.0.1", "robot": "10.78.0.2", "laptop": "10.78.0.3"}
ECHO_SERVER = """
import sys
import Peer, Peer__POA
from corba_peers import echo_servant
from miro_gen import Server
from miro_gen.lifecycle import run_main

def main():
    server = Server(sys.argv)
    server.add_to_name_service(echo_servant(Peer, Peer__POA), "Echo")
    print("ready", flush=True)
    server.run()

run_main(main, "echo")
"""


@pytest.fixture(scope="module")
def lan() -> Iterator[Hosts]:
    yield from network(LAN, tag="i")


@pytest.fixture(scope="module")
def cpp(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SimpleNamespace]:
    """The C++ omniORB peer and the generated Python types of its IDL."""
    if missing_tools():
        pytest.skip(f"needs {', '.join(missing_tools())}")
    from corba_peers import build_peer, generate_python

    out = tmp_path_factory.mktemp("peer_generated")
    generate_python(out)
    yield SimpleNamespace(binary=build_peer(), path=out)


def _naming(lan: Hosts, port: int, *options: str) -> str:
    endpoint = f"tcp://{LAN['nsbox']}:{port}"
    proc = lan.popen("nsbox", "-m", "miro_gen.cli.main", "naming", "--endpoint", endpoint, *options)
    assert proc.stdout is not None
    lines = [proc.stdout.readline()]
    while "WARNING" in lines[-1] and len(lines) < 5:  # --insecure's warnings come first
        lines.append(proc.stdout.readline())
    assert lines[-1].startswith(f"naming service at {endpoint}"), lines
    return endpoint


def _echo_server(
    lan: Hosts, cpp: SimpleNamespace, log: Path, *options: str
) -> subprocess.Popen[str]:
    """ECHO_SERVER on robot, with the fleet's key (MIRO_KEYS) and `options`."""
    lan.env["PYTHONPATH"] = f"{service_env()['PYTHONPATH']}:{cpp.path}:{REPO / 'tests'}"
    return lan.popen("robot", "-c", textwrap.dedent(ECHO_SERVER), *options, stderr=log)


def _cpp_client(lan: Hosts, cpp: SimpleNamespace, url: str) -> subprocess.CompletedProcess[str]:
    """omniORB's C++ client on the laptop, with no key of any kind: 20 calls to `url`."""
    return subprocess.run(
        ["ip", "netns", "exec", lan.ns("laptop"), str(cpp.binary), "bench", url, "20"],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_a_keyless_iiop_client_beyond_loopback_is_refused(
    lan: Hosts, cpp: SimpleNamespace, tmp_path: Path
) -> None:
    """A server with the fleet's key asked to serve IIOP on its network address stops at
    start-up, saying why in one line: the key covers ZeroMQ, not IIOP. Served on its loopback
    instead, it runs, and the laptop's key-less C++ client reaches nothing either way."""
    naming = _naming(lan, 2809)
    wide = f"{LAN['robot']}:7001"
    log = tmp_path / "wide.err"
    server = _echo_server(
        lan, cpp, log, "--naming", naming, "-MNC", "robot1", "--iiop-endpoint", wide
    )
    assert server.wait(60) == 2
    lines = log.read_text().strip().splitlines()
    assert len(lines) == 1 and "--insecure" in lines[0], lines
    assert f"IIOP on {wide} would be open to other machines, in the clear" in lines[0]
    refused = _cpp_client(lan, cpp, f"corbaloc:iiop:{wide}/robot1/Echo")
    assert refused.returncode != 0 and "TRANSIENT" in refused.stdout + refused.stderr

    log = tmp_path / "loopback.err"
    server = _echo_server(
        lan, cpp, log, "--naming", naming, "-MNC", "robot1", "--iiop-endpoint", "127.0.0.1:7001"
    )
    assert server.stdout is not None and server.stdout.readline() == "ready\n", log.read_text()
    for url in (f"corbaloc:iiop:{wide}/robot1/Echo", f"corbaloc:iiop:{LAN['robot']}:7001/x"):
        refused = _cpp_client(lan, cpp, url)
        assert refused.returncode != 0 and "TRANSIENT" in refused.stdout + refused.stderr
    lan.kill([server])


def test_with_insecure_the_cpp_client_beyond_loopback_is_served_and_told(
    lan: Hosts, cpp: SimpleNamespace, tmp_path: Path
) -> None:
    """--insecure opens IIOP to the network, and the server says so: omniORB's C++ client on
    the laptop, without any key, calls it."""
    naming = _naming(lan, 2810, "--insecure")
    log = tmp_path / "insecure.err"
    server = _echo_server(
        lan, cpp, log, "--insecure", "--naming", naming, "-MNC", "robot1",
        "--iiop-endpoint", f"{LAN['robot']}:7002",
    )  # fmt: skip
    assert server.stdout is not None and server.stdout.readline() == "ready\n", log.read_text()
    served = _cpp_client(lan, cpp, f"corbaloc:iiop:{LAN['robot']}:7002/robot1/Echo")
    assert served.returncode == 0, served.stdout + served.stderr
    assert served.stdout.startswith("P50 ")
    assert "in the clear (--insecure): anyone who can connect may call" in log.read_text()
    lan.kill([server])


def test_a_corba_naming_service_on_another_machine_needs_insecure(
    lan: Hosts, cpp: SimpleNamespace, tmp_path: Path
) -> None:
    """omniNames on nsbox: `miro nslist` on the laptop, with the fleet's key, refuses to talk
    IIOP to it in the clear; with --insecure it lists its names."""
    data = tmp_path / "omninames"
    data.mkdir()
    names = subprocess.Popen(
        ["ip", "netns", "exec", lan.ns("nsbox"), "omniNames", "-start", "2811",
         "-datadir", str(data), "-logdir", str(data)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        url = f"corbaloc:iiop:{LAN['nsbox']}:2811/NameService"
        deadline = time.monotonic() + 30
        while True:  # until omniNames answers (generous: only to avoid a hang)
            listed = lan.run("laptop", "-m", "miro_gen.cli.main", "nslist", "--naming", url)
            if "is a CORBA one" in listed.stderr or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert listed.returncode == 2, listed.stderr
        assert "is a CORBA one on another machine" in listed.stderr
        assert "--insecure" in listed.stderr
        listed = lan.run(
            "laptop", "-m", "miro_gen.cli.main", "nslist", "--naming", url, "--insecure"
        )
        assert listed.returncode == 0, listed.stderr
        assert "(no names bound)" in listed.stdout
    finally:
        names.kill()
        names.wait(10)
