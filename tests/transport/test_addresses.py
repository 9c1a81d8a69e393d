"""Which address a server binds on and advertises (miro_gen.transport.addresses).

The route lookup towards another host is replaced here where the machine's routes would decide
the answer; tests/transport/test_multihost.py runs it for real between network namespaces.
"""

from __future__ import annotations

import errno
import socket
import subprocess
import sys

import pytest
import zmq
from loopback import NamingProcess, service_env
from repo_paths import REPO

from miro_gen.service.options import UsageError
from miro_gen.transport import addresses
from miro_gen.transport.addresses import Addresses, route_source, server_addresses

SERVICES = REPO / "services"
NOT_OURS = "203.0.113.77"  # TEST-NET-3: documentation only, on no machine's interface
REMOTE_NAMING = "tcp://198.51.100.9:2810"  # TEST-NET-2


def not_ours() -> str:
    """NOT_OURS, unless this machine has it after all (then the test cannot say anything)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((NOT_OURS, 0))
        except OSError:
            return NOT_OURS
    pytest.skip(f"{NOT_OURS} is an address of this machine")


@pytest.fixture
def routes(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int]]:
    """Make every route lead out through 10.1.2.3; the routes asked for."""
    asked: list[tuple[str, int]] = []

    def fake(ip: str, port: int) -> str:
        asked.append((ip, port))
        return "10.1.2.3"

    monkeypatch.setattr(addresses, "route_source", fake)
    return asked


@pytest.mark.parametrize(
    "naming",
    ["tcp://127.0.0.1:2809", "tcp://localhost:2809", "tcp://127.0.0.5:1", "tcp://0.0.0.0:2809"],
)
def test_a_naming_service_on_loopback_keeps_everything_on_loopback(
    naming: str, routes: list[tuple[str, int]]
) -> None:
    assert server_addresses(naming, None) == Addresses("127.0.0.1", "127.0.0.1")
    assert routes == []


def test_a_remote_naming_service_gets_the_address_of_the_interface_towards_it(
    routes: list[tuple[str, int]],
) -> None:
    assert server_addresses(REMOTE_NAMING, None) == Addresses("0.0.0.0", "10.1.2.3")
    assert routes == [("198.51.100.9", 2810)]


def test_the_route_lookup_asks_the_kernel() -> None:
    assert route_source("127.0.0.1", 9) == "127.0.0.1"


def test_no_route_to_the_naming_service_suggests_host(monkeypatch: pytest.MonkeyPatch) -> None:
    def unreachable(ip: str, port: int) -> str:
        raise OSError(errno.ENETUNREACH, "Network is unreachable")

    monkeypatch.setattr(addresses, "route_source", unreachable)
    with pytest.raises(UsageError) as e:
        server_addresses(REMOTE_NAMING, None)
    assert str(e.value) == (
        f"this machine has no route to the naming service at {REMOTE_NAMING} "
        "(Network is unreachable); connect to its network or give --host ADDRESS"
    )


def test_a_naming_host_that_does_not_resolve(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_dns(*args: object) -> object:  # no waiting for a resolver the machine may lack
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", no_dns)
    with pytest.raises(UsageError, match=r"cannot resolve 'nsbox' \(Name or service not known\)"):
        server_addresses("tcp://nsbox:2809", None)


@pytest.mark.parametrize(
    ("host", "expected"),
    [
        ("127.0.0.1", Addresses("127.0.0.1", "127.0.0.1")),
        ("127.0.0.2", Addresses("127.0.0.2", "127.0.0.2")),  # a loopback address binds only itself
        ("localhost", Addresses("0.0.0.0", "localhost")),  # others may resolve a name otherwise
    ],
)
def test_host_is_advertised_as_given_and_wins(
    host: str, expected: Addresses, routes: list[tuple[str, int]]
) -> None:
    assert server_addresses(REMOTE_NAMING, host) == expected
    assert routes == []  # the naming host's route does not matter any more


def test_a_host_that_is_not_this_machines_is_refused() -> None:
    ip = not_ours()
    with pytest.raises(UsageError) as e:
        server_addresses("tcp://127.0.0.1:2809", ip)
    assert str(e.value).startswith(
        f"--host / MIRO_HOST '{ip}': {ip} is not an address of this machine; give one of its own "
        "addresses, or leave --host out"
    )


@pytest.mark.parametrize(
    ("naming", "host", "message"),
    [
        ("tcp://127.0.0.1:2809", "0.0.0.0", "others cannot connect to 0.0.0.0"),
        ("tcp://127.0.0.1:2809", "::1", "IPv4 only"),
        ("tcp://[::1]:2809", None, "IPv4 only"),
    ],
)
def test_addresses_that_cannot_be_advertised(naming: str, host: str | None, message: str) -> None:
    with pytest.raises(UsageError, match=message):
        server_addresses(naming, host)


def test_a_server_advertises_its_chosen_address() -> None:
    """The adapter's endpoint (what naming entries hold) follows the choice."""
    from miro_gen import Server

    server = Server(["t", "--host", "127.0.0.1"], context=zmq.Context())
    try:
        assert server.addresses == Addresses("127.0.0.1", "127.0.0.1")
        assert server.adapter.endpoint.startswith("tcp://127.0.0.1:")
        bound = server.adapter.bound
        assert bound.startswith("tcp://127.0.0.1:")  # not every interface
    finally:
        server.adapter.close()
        server.reactor().close()
        server.close()


@pytest.mark.parametrize("how", ["--host", "MIRO_HOST"])
def test_example_a_with_a_foreign_host_says_so_without_a_traceback(how: str) -> None:
    ip = not_ours()
    naming = NamingProcess()
    try:
        args = ["--naming", naming.endpoint] + (["--host", ip] if how == "--host" else [])
        env = service_env(**({"MIRO_HOST": ip} if how == "MIRO_HOST" else {}))
        a = subprocess.run(
            [sys.executable, str(SERVICES / "exampleA.py"), *args],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
    finally:
        naming.stop()
    assert a.returncode == 2
    assert a.stderr.startswith(f"exampleA: --host / MIRO_HOST '{ip}': {ip} is not an address of")
    assert "Traceback" not in a.stderr
    assert a.stdout == ""
