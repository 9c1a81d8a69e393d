"""A fleet on the Zenoh backbone: a base and three robots as Linux network namespaces joined by
veth links to a bridge (tests/netns.py makes them), `miro naming --zenoh` at the base
hosting the Zenoh router and the name registry, each robot's services its Zenoh clients; all
hold the fleet's key (netns.py gives it), so every link is mutual TLS (test_zenoh_security.py).

Shown here, across the links: every robot's names visible at the base; calls base -> robot; a
robot's events at the base through the router, all of them in order; a killed server's names
gone, and a cut link's once the link's lease ran out; a second session (on another robot)
declaring the queryable of a bound name's server answers no call. Outcomes are counted, not
timed; bench/bench_backbones.py has the seconds. Skipped where namespaces cannot be made.
"""

from __future__ import annotations

import json
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import eventually
from netns import Hosts, ip, network
from repo_paths import TESTS

pytest.importorskip("zenoh")

PROBE = str(TESTS / "procs" / "zenoh_probe.py")
ADDRESSES = {
    "base": "10.79.0.1",
    "robot1": "10.79.0.2",
    "robot2": "10.79.0.3",
    "robot3": "10.79.0.4",
}
NAMING = f"tcp://{ADDRESSES['base']}:2809"
ZENOH = ("--transport", "zenoh", "--naming", NAMING)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Hosts]:
    """The namespaces, `miro naming --zenoh` at the base, and ExampleA and ExampleB served by
    each robot (in its naming context)."""
    for hosts in network(ADDRESSES, tag="-z"):
        logs = tmp_path_factory.mktemp("fleet")
        naming = hosts.popen(
            "base", "-m", "miro_gen.cli.main", "naming", "--zenoh",
            "--endpoint", NAMING, "--log-file", "none", stderr=logs / "naming.err",
        )  # fmt: skip
        assert naming.stdout is not None
        line = naming.stdout.readline()
        assert line.startswith(f"naming service at {NAMING}"), (logs / "naming.err").read_text()
        for robot in ("robot1", "robot2", "robot3"):
            proc = hosts.popen(
                robot, str(TESTS / "procs" / "named_example.py"), *ZENOH, "-MNC", robot,
                "ExampleA", "ExampleB", stderr=logs / f"{robot}.err",
            )  # fmt: skip
            assert proc.stdout is not None
            assert proc.stdout.readline().strip() == "READY", (logs / f"{robot}.err").read_text()
        yield hosts


def probe(hosts: Hosts, host: str, *args: str) -> str:
    done = hosts.run(host, PROBE, NAMING, *args)
    assert done.returncode == 0, done.stderr
    return done.stdout


def names(hosts: Hosts, prefix: str = "") -> set[str]:
    return {line.split()[0] for line in probe(hosts, "base", "list", prefix).splitlines()}


def test_every_robots_names_are_visible_at_the_base_and_answer(fleet: Hosts) -> None:
    expected = {f"robot{i}/Example{x}" for i in (1, 2, 3) for x in "AB"}
    eventually(lambda: expected <= names(fleet), 20)
    for robot in ("robot1", "robot2", "robot3"):
        assert probe(fleet, "base", "call", f"{robot}/ExampleA", "5").strip() == "OK"
    assert probe(fleet, "robot1", "call", "robot3/ExampleB", "5").strip() == "OK"  # robot<->robot


def test_a_robots_events_reach_the_base_in_order_through_the_router(
    fleet: Hosts, tmp_path: Path
) -> None:
    printer = fleet.popen(
        "base", str(TESTS / "procs" / "event_printer.py"), *ZENOH, "-MNC", "base",
        "robot2/Events", stderr=tmp_path / "printer.err",
    )  # fmt: skip
    supplier = fleet.popen(
        "robot2", str(TESTS / "procs" / "channel_host.py"), *ZENOH, "-MNC", "robot2",
        "Events", stderr=tmp_path / "channel.err",
    )  # fmt: skip
    assert supplier.stdout is not None
    assert supplier.stdout.readline().strip() == "READY", (tmp_path / "channel.err").read_text()
    assert printer.stdout is not None
    assert printer.stdout.readline().strip() == "READY", (tmp_path / "printer.err").read_text()
    pushed = fleet.run(
        "robot1",
        str(TESTS / "procs" / "event_supplier.py"),
        *ZENOH,
        "-MNC",
        "robot1",
        "robot2/Events",
        "100",
        "20",
    )  # fmt: skip  (50 Hz, from another robot than the channel's)
    assert pushed.returncode == 0 and "DONE" in pushed.stdout, pushed.stderr
    seqs = []
    while len(seqs) < 100:
        line = printer.stdout.readline()
        assert line, (tmp_path / "printer.err").read_text()
        event = json.loads(line)
        assert event["domain"] == "robot1"
        seqs.append(event["seq"])
    assert seqs == list(range(seqs[0], seqs[0] + 100))
    fleet.kill([printer, supplier])


def test_a_second_session_cannot_answer_for_a_bound_name(fleet: Hosts, tmp_path: Path) -> None:
    rogue = fleet.popen("robot3", PROBE, NAMING, "rogue", "robot2/ExampleA",
                        stderr=tmp_path / "rogue.err")  # fmt: skip
    assert rogue.stdout is not None
    assert rogue.stdout.readline().strip() == "READY", (tmp_path / "rogue.err").read_text()
    assert probe(fleet, "base", "call", "robot2/ExampleA", "10").strip() == "OK"
    fleet.kill([rogue])


def test_a_killed_server_and_a_cut_robot_lose_their_names(fleet: Hosts) -> None:
    eventually(lambda: {"robot1/ExampleA", "robot3/ExampleA"} <= names(fleet), 20)
    killed = [p for p in fleet.procs if "robot1" in p.args and "named_example.py" in str(p.args)]
    assert len(killed) == 1
    killed[0].send_signal(signal.SIGKILL)
    killed[0].wait(10)
    eventually(lambda: not names(fleet, "robot1/"), 20)
    ip("-n", fleet.ns("hub"), "link", "set", "to-robot3", "down")  # robot3's link is cut
    try:
        eventually(lambda: not names(fleet, "robot3/"), 30)
    finally:
        ip("-n", fleet.ns("hub"), "link", "set", "to-robot3", "up")
    assert {"robot2/ExampleA", "robot2/ExampleB"} <= names(fleet, "robot2/")
