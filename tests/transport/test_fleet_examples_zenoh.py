"""The manual's examples A-D across a fleet on the Zenoh backbone, brought up by one launch file:
a base and three robots as Linux network namespaces (tests/netns.py), each running its part
with `miro launch fleet.toml --host NAME`.

The file says `transport = "zenoh"`, so the base's part is `miro naming --zenoh` (the router and
the name registry) and every service runs on Zenoh, under mutual TLS with the fleet's key that
every namespace's processes hold (MIRO_KEYS, tests/netns.py); it shares ExampleEvent of
ExampleEventChannel with the fleet (`fleet_events`, Miro's NotifyMulticast). Shown across the
links: ExampleB on robot2 polls ExampleA on robot1 (the manual's output); ExampleD on robot2
hears robot1's ExampleC on robot1's channel; ExampleD on robot3, on its own robot's channel,
hears robot1's events too, under robot1 as the domain, beside its own; `miro log record` at the
base records every robot's events from the fleet's channel. Outcomes are counted, not timed.
Skipped where namespaces cannot be made.
"""

from __future__ import annotations

import itertools
import queue
import re
import signal
import subprocess
import sys
import textwrap
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from manual_examples import MANUAL_OUTPUT
from netns import Hosts, network
from repo_paths import REPO

pytest.importorskip("zenoh")

SERVICES = REPO / "services"
ADDRESSES = {
    "base": "10.82.0.1",
    "robot1": "10.82.0.2",
    "robot2": "10.82.0.3",
    "robot3": "10.82.0.4",
}
NAMING = f"tcp://{ADDRESSES['base']}:2809"
FLEET_FILE = f"""
# A fleet on Zenoh: `miro launch fleet.toml --host NAME` on each machine.
[launch]
transport = "zenoh"
naming = "{NAMING}"
fleet_events = {{ ExampleEventChannel = ["ExampleEvent"] }}

[hosts.base]
address = "{ADDRESSES["base"]}"
[hosts.robot1]
address = "{ADDRESSES["robot1"]}"
[hosts.robot2]
address = "{ADDRESSES["robot2"]}"
[hosts.robot3]
address = "{ADDRESSES["robot3"]}"

[naming]
host = "base"
endpoint = "{NAMING}"

[services.exampleA]
host = "robot1"
context = "robot1"
run = "{SERVICES / "exampleA.py"}"

[services.exampleC]
host = "robot1"
context = "robot1"
run = "{SERVICES / "exampleC.py"}"
args = ["0.05"]

[services.exampleB]
host = "robot2"
context = "robot1"          # robot1's objects
run = "{SERVICES / "exampleB.py"}"
args = ["--period", "0.1", "--count", "4"]
after = ["robot1/ExampleA"]
restart = "never"

[services.exampleD]
host = "robot2"
context = "robot1"          # robot1's channel
run = "{SERVICES / "exampleD.py"}"
after = ["robot1/ExampleEventChannel"]

[services.exampleC3]
host = "robot3"
context = "robot3"
run = "{SERVICES / "exampleC.py"}"
args = ["0.05"]

[services.exampleD3]
host = "robot3"
context = "robot3"          # its own robot's channel: robot1's events come as the fleet's
run = "{SERVICES / "exampleD.py"}"
after = ["robot3/ExampleEventChannel"]
"""


class Launch:
    """`miro launch` of one host's part, its output read all the time by a thread (so that a
    full pipe never stops it) into a queue of lines."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put("")  # the end

    def skip(self) -> None:
        """Forget what was said so far: what `said` finds next comes after now."""
        while True:
            try:
                line = self.lines.get_nowait()
            except queue.Empty:
                return
            if not line:
                self.lines.put(line)  # (the end stays said)
                return
            self.seen.append(line)

    def said(self, label: str, text: str, count: int = 1) -> list[str]:
        """The next `count` lines by service `label` that hold `text` (the label's padding
        taken out); fails, with what was said, if the launch ends first (or says nothing for a
        minute: a guard against a hang)."""
        found: list[str] = []
        while len(found) < count:
            try:
                line = self.lines.get(timeout=60)
            except queue.Empty:
                line = ""
            assert line, "the launch ended or went silent:\n" + "".join(self.seen[-40:])
            self.seen.append(line)
            words = line.split()
            if words[:2] == [label, "|"] and text in line:
                found.append(" ".join(words[2:]))
        return found


@dataclass
class Fleet:
    hosts: Hosts
    launches: dict[str, Launch]
    logs: Path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    for hosts in network(ADDRESSES, tag="-zx"):
        logs = tmp_path_factory.mktemp("fleet-examples")
        path = logs / "fleet.toml"
        path.write_text(textwrap.dedent(FLEET_FILE).lstrip())
        launches = {}
        for host in ADDRESSES:  # the base first: the others wait for its router anyway
            launches[host] = Launch(hosts.popen(
                host, "-m", "miro_gen.cli.main", "launch", str(path), "--host", host,
                "--no-build", "--no-status", "--colour", "never",
            ))  # fmt: skip
        try:
            yield Fleet(hosts, launches, logs)
        finally:
            for launch in launches.values():
                if launch.proc.poll() is None:
                    launch.proc.send_signal(signal.SIGINT)
            for launch in launches.values():
                try:
                    launch.proc.wait(30)
                except subprocess.TimeoutExpired:
                    launch.proc.kill()


def test_example_b_on_robot2_polls_example_a_on_robot1(fleet: Fleet) -> None:
    lines = fleet.launches["robot2"].said("exampleB", "", 8)
    assert "\n".join(lines) + "\n" == MANUAL_OUTPUT


def received(launch: Launch, label: str, robots: set[str], each: int) -> dict[str, list[int]]:
    """The counters of the ExampleEvents service `label` says it received, by the robot they
    came from (its domain), read until each of `robots` has `each` (fails after 40 times as
    many events without that)."""
    got: dict[str, list[int]] = {}
    for _ in range(40 * each * len(robots)):
        if all(len(got.get(r, [])) >= each for r in robots):
            return got
        (line,) = launch.said(label, "Received ExampleEvent #")
        m = re.match(r"Received ExampleEvent #(\d+) from ([^:]+):", line)
        assert m is not None, line
        got.setdefault(m.group(2), []).append(int(m.group(1)))
    raise AssertionError(f"{label} did not hear {each} events of each of {sorted(robots)}: {got}")


def in_order_once(counters: list[int]) -> bool:
    """Each event once, in the order sent (one the consumer's queue dropped under load is a
    gap its sequence numbers show, not an error here)."""
    return all(a < b for a, b in itertools.pairwise(counters))


def test_example_d_on_robot2_hears_example_c_on_robot1(fleet: Fleet) -> None:
    got = received(fleet.launches["robot2"], "exampleD", {"robot1"}, 10)
    assert in_order_once(got["robot1"]), got


def test_robot3s_own_channel_hears_robot1s_shared_events_under_robot1(fleet: Fleet) -> None:
    got = received(fleet.launches["robot3"], "exampleD3", {"robot1", "robot3"}, 10)
    assert set(got) == {"robot1", "robot3"}, got  # robot2 supplies nothing
    assert all(in_order_once(c) for c in got.values()), got  # none twice


def test_the_base_records_every_robots_events(fleet: Fleet) -> None:
    log = fleet.logs / "fleet.mcap"
    env = dict(fleet.hosts.env, MIRO_TRANSPORT="zenoh")
    rec = subprocess.Popen(
        [*fleet.hosts.wrapper("base"), "MIRO_TRANSPORT=zenoh", sys.executable,
         "-m", "miro_gen.cli.main", "log", "record", "--naming", NAMING,
         "--channel", "*/ExampleEventChannel", "-o", str(log)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        assert rec.stderr is not None
        assert rec.stderr.readline().startswith("recording ")
        # a few more events of each robot after the recorder is up
        fleet.launches["robot3"].skip()
        fleet.launches["robot3"].said("exampleD3", "from robot1:", 10)
        fleet.launches["robot3"].said("exampleD3", "from robot3:", 10)
        rec.send_signal(signal.SIGINT)
        _, err = rec.communicate(timeout=30)
        assert rec.returncode in (0, 130), err  # (130: 128 + SIGINT, as after Ctrl-C)
    finally:
        if rec.poll() is None:
            rec.kill()
            rec.wait(10)
    info = fleet.hosts.run("base", "-m", "miro_gen.cli.main", "log", "info", str(log))
    assert info.returncode == 0, info.stderr
    counts = {line.split()[0]: int(line.split()[2]) for line in info.stdout.splitlines()
              if "events" in line and "/" in line.split()[0]}  # fmt: skip
    assert set(counts) == {"robot1/ExampleEvent", "robot3/ExampleEvent"}, info.stdout
    assert min(counts.values()) >= 1, info.stdout
