"""Access control per robot at the Zenoh router (`miro naming --zenoh --per-robot`, Zenoh's
`access_control` by certificate common name: transport/zenoh/access.py), between network
namespaces: a base holding the fleet's key and two robots, each with its own certificate of
the fleet's CA (`miro keys new robotN --ca fleet`). Robot 2's certificate cannot answer for
robot 1's objects nor publish under robot 1's domain (the router drops it: nothing of it
reaches the base), while robot 2's own objects and events work. Outcomes are counted."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import free_port, run_miro, service_env
from netns import Hosts, network
from repo_paths import TESTS

from miro_gen.transport.tlsfiles import base_of

pytest.importorskip("zenoh")

ADDRESSES = {"base": "10.84.0.1", "robot1": "10.84.0.2", "robot2": "10.84.0.3"}
NAMING = f"tcp://{ADDRESSES['base']}:2809"
ZENOH = ("--transport", "zenoh", "--naming", NAMING)
PROBE = str(TESTS / "procs" / "zenoh_probe.py")
PROCS = TESTS / "procs"


def robot_env(hosts: Hosts, robot: str) -> dict[str, str]:
    """The environment of `robot`'s processes: its own key, beside the fleet's."""
    return {**hosts.env, "MIRO_KEYS": str(Path(base_of(hosts.env["MIRO_KEYS"])).parent / robot)}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Hosts]:
    """The namespaces, robots' keys, the router with access per robot, and ExampleA served by
    each robot in its own context with its own key."""
    for hosts in network(ADDRESSES, tag="-acl"):
        fleet_key = base_of(hosts.env["MIRO_KEYS"])
        for robot in ("robot1", "robot2"):
            made = subprocess.run(
                [sys.executable, "-m", "miro_gen.cli.main", "keys", "new",
                 str(Path(fleet_key).parent / robot), "--ca", fleet_key],
                capture_output=True, text=True, env=service_env(), timeout=60,
            )  # fmt: skip
            assert made.returncode == 0, made.stderr
        logs = tmp_path_factory.mktemp("acl")
        naming = hosts.popen(
            "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", NAMING,
            "--log-file", "none", "--per-robot", "robot1,robot2", "--channel", "Events",
            stderr=logs / "naming.err",
        )  # fmt: skip
        assert naming.stdout is not None
        line = naming.stdout.readline()
        assert "access per robot: robot1, robot2 only their own keys" in line, (
            line + (logs / "naming.err").read_text()
        )
        for robot in ("robot1", "robot2"):
            proc = hosts.popen(
                robot, str(PROCS / "named_example.py"), *ZENOH, "-MNC", robot, "ExampleA",
                stderr=logs / f"{robot}.err", env=robot_env(hosts, robot),
            )  # fmt: skip
            assert proc.stdout is not None
            assert proc.stdout.readline().strip() == "READY", (logs / f"{robot}.err").read_text()
        yield hosts


def probe(hosts: Hosts, host: str, *args: str, env: dict[str, str] | None = None) -> str:
    done = hosts.run(host, PROBE, NAMING, *args, env=env)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_robot_cannot_answer_for_another_robots_objects(fleet: Hosts, tmp_path: Path) -> None:
    err = tmp_path / "rogue.err"
    rogue = fleet.popen(
        "robot2",
        PROBE,
        NAMING,
        "rogue",
        "robot1/ExampleA",
        stderr=err,
        env=robot_env(fleet, "robot2"),
    )  # fmt: skip  (robot2's certificate, on robot1's call key)
    assert rogue.stdout is not None
    assert rogue.stdout.readline().strip() == "READY", err.read_text()
    assert probe(fleet, "base", "call", "robot1/ExampleA", "10").strip() == "OK"
    # robot2's own objects, called from the base and from robot1 (with robot1's key)
    assert probe(fleet, "base", "call", "robot2/ExampleA", "3").strip() == "OK"
    mine = robot_env(fleet, "robot1")
    assert probe(fleet, "robot1", "call", "robot2/ExampleA", "3", env=mine).strip() == "OK"
    fleet.kill([rogue])
    assert "HEARD" not in err.read_text()  # the router never passed it a call


def test_a_robot_cannot_publish_under_another_robots_domain(fleet: Hosts, tmp_path: Path) -> None:
    printer = fleet.popen(
        "base", str(PROCS / "event_printer.py"), *ZENOH, "-MNC", "base", "Events",
        stderr=tmp_path / "printer.err",
    )  # fmt: skip
    assert printer.stdout is not None
    assert printer.stdout.readline().strip() == "READY", (tmp_path / "printer.err").read_text()
    robot2 = robot_env(fleet, "robot2")
    for domain in ("robot1", "robot2"):  # robot1's domain first: dropped at the router
        pushed = fleet.run(
            "robot2", str(PROCS / "event_supplier.py"), *ZENOH, "-MNC", domain, "Events",
            "20", "5", env=robot2,
        )  # fmt: skip
        assert pushed.returncode == 0 and "DONE" in pushed.stdout, pushed.stderr
    domains = []
    while len(domains) < 20:
        line = printer.stdout.readline()
        assert line, (tmp_path / "printer.err").read_text()
        domains.append(json.loads(line)["domain"])
    assert domains == ["robot2"] * 20
    fleet.kill([printer])


def test_access_per_robot_needs_zenoh_and_a_key() -> None:
    """Without certificates there is nothing to tell robots by: one line, status 2."""
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    for extra in ([], ["--zenoh"]):
        done = run_miro("naming", *extra, "--endpoint", endpoint, "--per-robot", "robot1")
        assert done.returncode == 2, done.stderr
        assert done.stderr.splitlines()[-1].endswith(
            "--per-robot takes robots' names, and needs --zenoh and a key (mutual TLS: the "
            "router tells robots by their certificates); give --keys FILE"
        ), done.stderr
