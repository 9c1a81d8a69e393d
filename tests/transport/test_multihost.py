"""The naming service, a server and a client on three "machines": Linux network namespaces
joined by veth links to a bridge (in a fourth, hub namespace), with addresses in 10.77.0.0/24.

Each namespace has its own interfaces, routes and loopback, so a server that advertised
127.0.0.1, or bound only loopback, could not be reached from the others; that is what these
tests would catch. Beyond loopback the transport needs the robot's or fleet's key (CURVE): every
process here gets one made by `miro keys new` (MIRO_KEYS), and a process without it is
refused. Creating namespaces needs root and iproute2 (`ip netns`); without them, or where
`ip netns add` is refused (a container without CAP_SYS_ADMIN), the tests are skipped and say
why.
"""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import service_env
from manual_examples import MANUAL_OUTPUT, read_lines
from netns import ADDRESSES, Hosts, network
from repo_paths import REPO

SERVICES = REPO / "services"
NAMING = f"tcp://{ADDRESSES['nsbox']}:2809"
NSC = ["-ORBInitRef", f"NameService=iioploc://{ADDRESSES['nsbox']}:2809/NameService"]


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    yield from network()


@pytest.fixture(scope="module")
def naming(hosts: Hosts, tmp_path_factory: pytest.TempPathFactory) -> subprocess.Popen[str]:
    """`miro naming` on nsbox's own address (not 0.0.0.0), as on a real naming host."""
    log = tmp_path_factory.mktemp("nsbox") / "naming.err"
    proc = hosts.popen(
        "nsbox", "-m", "miro_gen.cli.main", "naming", "--endpoint", NAMING, stderr=log
    )
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()
    assert line.startswith(f"naming service at {NAMING}; CURVE with the key "), log.read_text()
    return proc


@pytest.fixture
def net(hosts: Hosts, naming: subprocess.Popen[str]) -> Iterator[Hosts]:
    """The hosts with the naming service running; what the test starts is killed after it, even
    when it fails, so the next test sees none of its names."""
    before = len(hosts.procs)
    yield hosts
    hosts.kill(hosts.procs[before:])


def nslist(hosts: Hosts) -> str:
    """What `miro nslist` shows from the laptop."""
    done = hosts.run("laptop", "-m", "miro_gen.cli.main", "nslist", "--naming", NAMING)
    assert done.returncode == 0, done.stderr
    return done.stdout


def stop(proc: subprocess.Popen[str], log: Path) -> None:
    proc.send_signal(signal.SIGINT)
    assert proc.wait(10) == 0, log.read_text()


def test_example_b_on_a_laptop_polls_example_a_on_a_robot(net: Hosts, tmp_path: Path) -> None:
    """§5.1 across machines: ExampleA on robot advertises robot's address; ExampleB on laptop
    finds it through nsbox and prints what the manual shows."""
    a_log = tmp_path / "exampleA.err"
    a = net.popen(
        "robot", str(SERVICES / "exampleA.py"), *NSC, "-MNC", "robot1", "-MLL", "9", stderr=a_log
    )
    assert a.stdout is not None and a.stdout.readline().strip() == "ExampleA is ready", (
        a_log.read_text()
    )
    listing = nslist(net)
    assert f"ExampleA  (IDL:Miro/Example:1.0 at tcp://{ADDRESSES['robot']}:" in listing, listing
    assert "127.0.0.1" not in listing
    b = net.run(
        "laptop",
        str(SERVICES / "exampleB.py"),
        "--naming",
        NAMING,
        "-MNC",
        "robot1",
        "--count",
        "4",
        "--period",
        "0",
    )
    assert b.returncode == 0, b.stderr
    assert b.stdout.startswith(MANUAL_OUTPUT)
    stop(a, a_log)
    assert "[DEBUG MIRO] setData(0, 10)" in a_log.read_text()
    assert "ExampleA" not in nslist(net)  # unbound on the way out, across the link too


def test_example_d_on_a_laptop_receives_example_c_on_a_robot(net: Hosts, tmp_path: Path) -> None:
    """§5.2 across machines: the channel is hosted on robot, and laptop's consumer connects to
    the endpoints robot advertises."""
    c_log, d_log = tmp_path / "exampleC.err", tmp_path / "exampleD.err"
    c = net.popen(
        "robot", str(SERVICES / "exampleC.py"), *NSC, "-MNC", "robot1", "0.05", stderr=c_log
    )
    assert read_lines(c, "ExampleC publishes", 1) == [
        "ExampleC publishes ExampleEvent on robot1/ExampleEventChannel every 0.05 s"
    ], c_log.read_text()
    listing = nslist(net)
    channel = "ExampleEventChannel  (IDL:miro-gen/EventChannel:1.0 at tcp://"
    assert f"{channel}{ADDRESSES['robot']}:" in listing, listing
    d = net.popen(
        "laptop", str(SERVICES / "exampleD.py"), "--naming", NAMING, "-MNC", "robot1", stderr=d_log
    )
    got = read_lines(d, "Received ExampleEvent #", 5)
    assert len(got) == 5, (got, d_log.read_text())
    counters = [int(line.split("#")[1].split()[0]) for line in got]
    assert counters == list(range(counters[0], counters[0] + 5))  # in order, none lost
    k = counters[0]
    assert got[0] == f"Received ExampleEvent #{k} from robot1: a = {k}, b = {10 + k}"
    stop(d, d_log)
    stop(c, c_log)


def test_a_laptop_without_the_key_is_refused(net: Hosts, tmp_path: Path) -> None:
    """The fleet's naming service, and everything else beyond loopback, speaks CURVE: a process
    without the key (here one that insists on --insecure) cannot even list the names."""
    env = service_env(HOME=str(tmp_path))  # no default key either
    done = net.run(
        "laptop", "-m", "miro_gen.cli.main", "nslist", "--naming", NAMING, "--insecure", env=env
    )
    assert done.returncode == 1
    assert "refused the connection" in done.stderr, done.stderr
    no_key = net.run("laptop", "-m", "miro_gen.cli.main", "nslist", "--naming", NAMING, env=env)
    assert no_key.returncode == 2 and "--keys" in no_key.stderr, no_key.stderr


def test_a_server_told_to_advertise_loopback_is_unreachable_from_another_host(
    net: Hosts, tmp_path: Path
) -> None:
    """What the default used to do: the client resolves the name, then cannot reach 127.0.0.1
    on its own machine, and says where it tried (no traceback)."""
    a_log = tmp_path / "exampleA.err"
    a = net.popen(
        "robot",
        str(SERVICES / "exampleA.py"),
        *NSC,
        "-MNC",
        "robot2",
        "--host",
        "127.0.0.1",
        stderr=a_log,
    )
    assert a.stdout is not None and a.stdout.readline().strip() == "ExampleA is ready", (
        a_log.read_text()
    )
    b = net.run(
        "laptop",
        str(SERVICES / "exampleB.py"),
        "--naming",
        NAMING,
        "-MNC",
        "robot2",
        "--count",
        "1",
    )
    assert b.returncode == 1
    assert b.stderr.startswith("exampleB: cannot reach tcp://127.0.0.1:"), b.stderr
    assert "Traceback" not in b.stderr
    stop(a, a_log)
