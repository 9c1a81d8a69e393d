"""Issue 19's "done when": a robot brought up from one launch file on two hosts (network
namespaces) that find each other by discovery only; one service killed and seen restarted and
bound again; an operation called and an event published from the shell; a parameter changed
live and used by the driver; and one Ctrl-C per host stopping everything, no process left.

The base station runs the naming service (on every interface, announced), ExampleB and ExampleD;
the robot runs ExampleA, ExampleC and the GPS driver on a simulated receiver, and knows no
address: its launch and its shell tools find the naming service by its announcement.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import eventually
from miro_cli import REPO
from netns import Hosts, network
from test_launch import alive, started_pids

from miro_gen.testing import ServiceProcess

SERVICES = REPO / "services"
ADDRESSES = {"base": "10.78.0.1", "robot": "10.78.0.2"}


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    yield from network(ADDRESSES, tag="b")


def launch_file(folder: Path) -> Path:
    path = folder / "robot.toml"
    path.write_text(
        textwrap.dedent(
            f"""
            [launch]
            context = "robot1"
            grace = 3

            [hosts.base]
            [hosts.robot]

            [naming]
            host = "base"
            endpoint = "tcp://0.0.0.0:2809"  # every interface, announced: the robot finds it

            [services.sim]
            host = "robot"
            command = ["miro", "sim", "nmea", "--link", "{folder}/gps0", "--rate", "5"]
            ready = "NMEA on"

            [services.gps]
            host = "robot"
            run = "{SERVICES}/gps"
            after = ["sim"]
            parameters.Gps.Gps = {{ Device = "{folder}/gps0" }}

            [services.exampleA]
            host = "robot"
            run = "{SERVICES}/exampleA.py"
            restart = "always"
            restart_delay = 0.2

            [services.exampleC]
            host = "robot"
            run = "{SERVICES}/exampleC.py"
            args = ["0.3"]

            [services.exampleB]
            host = "base"
            run = "{SERVICES}/exampleB.py"
            args = ["--period", "0.3"]
            after = ["robot1/ExampleA"]
            restart_delay = 0.2

            [services.exampleD]
            host = "base"
            run = "{SERVICES}/exampleD.py"
            after = ["robot1/ExampleEventChannel"]
            """
        )
    )
    return path


def test_a_robot_on_two_hosts_found_by_discovery_and_operated_live(
    hosts: Hosts, tmp_path: Path
) -> None:
    robot_toml = launch_file(tmp_path)
    cache = tmp_path / "cache"

    def launch(host: str) -> ServiceProcess:
        return ServiceProcess(
            "miro_gen.cli.main",
            "launch",
            str(robot_toml),
            "--host",
            host,
            cwd=REPO,
            wrapper=hosts.wrapper(host),
        )

    def shell(*args: str) -> subprocess.CompletedProcess[str]:
        """A miro command typed on the robot, which knows no address."""
        on_robot = ["ip", "netns", "exec", hosts.ns("robot"), sys.executable]
        return subprocess.run(
            [*on_robot, "-m", "miro_gen.cli.main", *args],
            capture_output=True,
            text=True,
            env={**hosts.env, "MIRO_CACHE": str(cache)},
            timeout=60,
        )

    base = launch("base")
    robot = launch("robot")
    try:
        robot.wait_for("naming service found at tcp://10.78.0.1:2809")
        base.wait_for("| Retrieved variables a and b are:")
        base.wait_for("| Received ExampleEvent #", count=2)
        robot.wait_for("| gps: reading")

        # kill ExampleA: restarted, bound again at its new port, and polled again
        old = robot.wait_for("exampleA started, pid")[0]
        pid = int(old.rsplit(" ", 1)[1])
        listing = shell("nslist")
        assert "ExampleA  (IDL:Miro/Example:1.0 at tcp://10.78.0.2:" in listing.stdout, listing
        subprocess.run(["kill", "-9", str(pid)], check=True)
        robot.wait_for("exampleA exited with SIGKILL; restart 1")
        robot.wait_for("| ExampleA is ready", count=2)
        eventually(lambda: shell("nslist").stdout != listing.stdout, 60)
        done = shell("call", "robot1/ExampleA", "setData", "7", "8")
        assert done.returncode == 0, done.stderr
        got = shell("call", "robot1/ExampleA", "getData")  # ExampleB sets it too, meanwhile
        assert re.fullmatch(r"a: [\d.]+\nb: [\d.]+\n", got.stdout), got.stderr
        before = len([t for t in base.lines if "Retrieved variables" in t])
        base.wait_for("| Retrieved variables a and b are:", count=before + 2)

        # publish by hand: ExampleD, on the base, receives it
        done = shell("pub", "robot1/ExampleEvent", "{counter: 77, data: {a: 7, b: 8}}")
        assert done.returncode == 0, done.stderr
        base.wait_for("| Received ExampleEvent #77 from robot1: a = 7, b = 8")

        # a parameter changed live, and the driver uses it at once
        assert shell("call", "robot1/Gps", "getWaitData").returncode == 0
        done = shell("param", "set", "gps", "Gps.WaitTimeout", "0, 1")
        assert done.stdout == "Gps/Gps.WaitTimeout = 0, 1\n", done.stderr
        late = shell("call", "robot1/Gps", "getWaitData")
        assert late.stderr.startswith("robot1/Gps getWaitData raised IDL:Miro/ETimeOut:1.0")
    finally:
        started = started_pids(robot) + started_pids(base)
        for proc in (robot, base):  # one Ctrl-C each
            proc.proc.send_signal(signal.SIGINT)
        codes = [proc.proc.wait(60) for proc in (robot, base)]
        robot.stop()
        base.stop()
    assert codes == [0, 0], robot.output + "\n" + base.output
    for pid in started:
        eventually(lambda pid=pid: not alive(pid))  # type: ignore[misc]
