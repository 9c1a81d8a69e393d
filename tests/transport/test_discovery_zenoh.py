"""Discovery on the Zenoh backbone: `miro naming --zenoh` announces its router with DNS-SD over
multicast DNS (the record of transport.naming.discovery, with the router's locator in its
`zenoh` TXT key), and a robot's processes given no naming address find it as ZeroMQ processes
find `miro naming`; `miro doctor` shows it. Between network namespaces holding the fleet's
key (tests/netns.py), so the links are mutual TLS. Outcomes, not seconds:
bench/bench_discovery_zenoh.py times them."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from netns import Hosts, network
from repo_paths import TESTS

pytest.importorskip("zenoh")

ADDRESSES = {"base": "10.83.0.1", "robot": "10.83.0.2"}
NAMING = f"tcp://{ADDRESSES['base']}:2809"
PROBE = str(TESTS / "procs" / "zenoh_probe.py")


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    yield from network(ADDRESSES, tag="-dz")


@pytest.fixture(scope="module")
def router(hosts: Hosts) -> Hosts:
    """`miro naming --zenoh` at the base, once it said it announced itself."""
    naming = hosts.popen(
        "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", NAMING,
        "--log-file", "none", "-MLL", "5",
    )  # fmt: skip
    assert naming.stdout is not None
    lines = []
    for line in naming.stdout:
        lines.append(line)
        if "announced as" in line:
            return hosts
    raise AssertionError("the router never announced itself:\n" + "".join(lines))


def test_a_robot_without_an_address_finds_the_announced_router(
    router: Hosts, tmp_path: Path
) -> None:
    hosts = router
    doctor = hosts.run("robot", "-m", "miro_gen.cli.main", "doctor", "--timeout", "2")
    assert (
        f"({ADDRESSES['base']}), port 2809 (Zenoh router tls/{ADDRESSES['base']}:2809, for "
        f"--transport zenoh): answers at {NAMING}"
    ) in doctor.stdout, doctor.stdout + doctor.stderr
    server = hosts.popen(
        "robot",
        str(TESTS / "procs" / "named_example.py"),
        "--transport",
        "zenoh",
        "-MNC",
        "robot1",
        "-MLL",
        "5",
        "ExampleA",
        stderr=tmp_path / "server.err",
    )  # fmt: skip  (no --naming, no MIRO_NAMING)
    assert server.stdout is not None
    assert server.stdout.readline().strip() == "READY", (tmp_path / "server.err").read_text()
    said = (tmp_path / "server.err").read_text()
    assert f"using {NAMING} (Zenoh router tls/{ADDRESSES['base']}:2809)" in said, said
    called = hosts.run("base", PROBE, NAMING, "call", "robot1/ExampleA", "5")
    assert called.stdout.strip() == "OK", called.stderr
    listed = hosts.run("robot", "-m", "miro_gen.cli.main", "call", "--transport", "zenoh",
                       "robot1/ExampleA", "getData")  # fmt: skip
    assert listed.returncode == 0, listed.stderr
    assert "5.0" in listed.stdout, listed.stdout


def test_a_zeromq_process_does_not_take_the_router_for_its_naming_service(
    router: Hosts,
) -> None:
    """The router is announced as a naming service of the other backbone: a ZeroMQ process
    without an address skips it and fails as with nothing announced."""
    done = router.run("robot", "-m", "miro_gen.cli.main", "nslist", "-MLL", "5")
    assert done.returncode != 0
    assert ADDRESSES["base"] not in done.stdout + done.stderr, done.stderr
