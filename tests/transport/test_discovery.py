"""Discovery (the manual's `Naming_Service -m 1`): `miro naming` announces itself with DNS-SD
over multicast DNS, processes given no naming service find it, and `miro doctor` says what is
visible and why a connection fails. Between network namespaces, as the multi-host tests."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator

import pytest
from loopback import free_port, run_miro, service_env
from netns import Hosts, ip, network
from repo_paths import REPO

from miro_gen.transport.naming.discovery import answers

ADDRESSES = {"nsbox": "10.79.0.1", "robot": "10.79.0.2"}
SERVICES = REPO / "services"


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    yield from network(ADDRESSES, tag="d")


def naming(hosts: Hosts, *args: str) -> subprocess.Popen[str]:
    proc = hosts.popen("nsbox", "-m", "miro_gen.cli.main", "naming", "-MLL", "5", *args)
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith("naming service at ")
    return proc


def announced(proc: subprocess.Popen[str]) -> None:
    """Wait until the naming service says it announced itself (a second or two of probing)."""
    assert proc.stdout is not None
    for line in proc.stdout:
        if "announced as" in line:
            return
    raise AssertionError("the naming service never announced itself")


def test_a_service_without_an_address_finds_the_announced_naming_service(hosts: Hosts) -> None:
    ns = naming(hosts, "-ORBEndpoint", "iiop://10.79.0.1:2809")  # the manual's spelling
    try:
        announced(ns)
        doctor = hosts.run("robot", "-m", "miro_gen.cli.main", "doctor", "--timeout", "2")
        lines = doctor.stdout.splitlines()
        assert lines[0] == (
            "tcp://127.0.0.1:2809: nothing listens there (the naming service is not running, "
            "or a firewall refuses)"
        )
        assert lines[1] == "this machine's networks: eth0 10.79.0.0/24"
        assert lines[2].endswith("(10.79.0.1), port 2809: answers at tcp://10.79.0.1:2809")
        a = hosts.popen("robot", str(SERVICES / "exampleA.py"), "-MNC", "robot1")
        assert a.stdout is not None and a.stdout.readline().strip() == "ExampleA is ready"
        listing = hosts.run("robot", "-m", "miro_gen.cli.main", "nslist")
        assert "ExampleA  (IDL:Miro/Example:1.0 at tcp://10.79.0.2:" in listing.stdout
        hosts.kill([a])
    finally:
        hosts.kill([ns])


def test_doctor_explains_an_unannounced_and_an_unreachable_naming_service(hosts: Hosts) -> None:
    quiet = naming(hosts, "--endpoint", "tcp://10.79.0.1:2809", "-m", "0")
    nsbox = hosts.ns("nsbox")
    ip("-n", nsbox, "link", "add", "lab0", "type", "veth", "peer", "name", "lab1")  # a 2nd NIC
    ip("-n", nsbox, "addr", "add", "10.80.0.1/24", "dev", "lab0")
    ip("-n", nsbox, "link", "set", "lab0", "up")
    ip("-n", nsbox, "link", "set", "lab1", "up")
    elsewhere = naming(hosts, "--endpoint", "tcp://10.80.0.1:2810")  # on a network robot lacks
    try:
        announced(elsewhere)
        doctor = hosts.run("robot", "-m", "miro_gen.cli.main", "doctor", "--timeout", "2")
        out = doctor.stdout
        assert "port 2809" not in out  # -m 0: not announced
        assert (
            "(10.80.0.1), port 2810: tcp://10.80.0.1:2810: no route to it from this machine "
            "(another network, or the wrong interface); it is on none of this machine's "
            "networks" in out
        ), out
    finally:
        hosts.kill([quiet, elsewhere])
        ip("-n", nsbox, "link", "delete", "lab0")


def test_nothing_listening_is_said_so() -> None:
    assert answers(f"tcp://127.0.0.1:{free_port()}").startswith("nothing listens there")


def test_the_manuals_endpoint_spelling_is_checked() -> None:
    done = run_miro("naming", "-ORBEndpoint", "corbaloc:nowhere")
    assert done.returncode == 2
    assert "-ORBEndpoint takes iiop://HOST:PORT, not 'corbaloc:nowhere'" in done.stderr


def test_outside_their_namespaces_the_tests_send_no_multicast_dns() -> None:
    """conftest.py turns multicast DNS off for every test and what it starts: a naming service
    bound to every interface is not announced, and nothing is looked for."""
    assert os.environ["MIRO_DISCOVERY"] == "0"
    ns = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint",
         f"tcp://0.0.0.0:{free_port()}", "--insecure", "-MLL", "5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=service_env(),
    )  # fmt: skip
    try:
        assert ns.stdout is not None and ns.stdout.readline().startswith("naming service at")
    finally:
        ns.terminate()
        _, err = ns.communicate(timeout=30)
    assert "not announced on the network: multicast DNS is off here (MIRO_DISCOVERY=0)" in err
    assert "announced as" not in err
    doctor = run_miro("doctor", "--timeout", "1")
    assert (
        "cannot look for announced naming services (multicast DNS): multicast DNS is off here "
        "(MIRO_DISCOVERY=0)"
    ) in doctor.stdout, doctor.stdout + doctor.stderr
