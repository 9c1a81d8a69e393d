"""The Zenoh backbone's security across hosts (issue 26), in network namespaces the test makes
(tests/netns.py): `miro naming --zenoh` at the base with the fleet's key (mutual TLS), robots
in namespaces of their own. ZeroMQ's defaults: beyond loopback a key or `--insecure`.

Shown: with keys (the fleet's, or a robot's own certificate of the fleet's CA), a call and an
event cross; without a key a robot does not start (one line), and a robot in the clear or with
another fleet's key is refused by the router: it waits, and binds no name; with `--insecure`
on both sides it works. Loopback without keys: test_zenoh_keys.py. Skipped where namespaces
cannot be made.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import eventually
from netns import Hosts, network
from repo_paths import TESTS

pytest.importorskip("zenoh")
pytest.importorskip("cryptography")

PROBE = str(TESTS / "procs" / "zenoh_probe.py")
EXAMPLE = str(TESTS / "procs" / "named_example.py")
ADDRESSES = {"base": "10.83.0.1", "robot": "10.83.0.2", "intruder": "10.83.0.3"}
NAMING = f"tcp://{ADDRESSES['base']}:2809"  # the keyed router
OPEN = f"tcp://{ADDRESSES['base']}:2810"  # the --insecure one


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Hosts, Path]]:
    """The namespaces (every process holds the fleet's key, MIRO_KEYS, unless a test says
    otherwise), a robot's own certificate of the fleet's CA and another fleet's key, and
    `miro naming --zenoh` at the base with the fleet's key."""
    for hosts in network(ADDRESSES, tag="-zs"):
        keys = tmp_path_factory.mktemp("keys")
        fleet = hosts.env["MIRO_KEYS"]
        for args in (["robot", "--ca", fleet], ["other"]):
            made = subprocess.run(
                [sys.executable, "-m", "miro_gen.cli.main", "keys", "new", str(keys / args[0]),
                 *args[1:]],
                capture_output=True, text=True, env=hosts.env, timeout=60,
            )  # fmt: skip
            assert made.returncode == 0, made.stderr
        naming = hosts.popen(
            "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", NAMING,
            "--log-file", "none", stderr=keys / "naming.err",
        )  # fmt: skip
        assert naming.stdout is not None
        line = naming.stdout.readline()
        assert line.startswith(f"naming service at {NAMING}"), (keys / "naming.err").read_text()
        assert "mutual TLS at tls/10.83.0.1:2809 with the key fleet" in line
        yield hosts, keys


def start(hosts: Hosts, host: str, argv: list[str], err: Path, **env: str) -> subprocess.Popen[str]:
    """`argv` in `host`'s namespace with `env` over the hosts' environment (an empty value
    removes the variable), stderr to `err`; killed with the namespaces."""
    environment = {k: v for k, v in {**hosts.env, **env}.items() if v}
    with err.open("w") as stderr:
        proc = subprocess.Popen(
            ["ip", "netns", "exec", hosts.ns(host), sys.executable, *argv],
            stdout=subprocess.PIPE, stderr=stderr, text=True, env=environment,
        )  # fmt: skip
    hosts.procs.append(proc)
    return proc


def ready(proc: subprocess.Popen[str], err: Path) -> None:
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "READY", err.read_text()


def waiting(err: Path) -> None:
    """Until the server whose stderr is `err` says it waits for the router."""
    eventually(lambda: "waiting for the Zenoh router" in err.read_text(), 30)


def probe(hosts: Hosts, naming: str, *args: str) -> str:
    done = hosts.run("base", PROBE, naming, *args)
    assert done.returncode == 0, done.stderr
    return done.stdout


def names(hosts: Hosts, naming: str = NAMING, *options: str) -> set[str]:
    listed = probe(hosts, naming, "list", "", *options).splitlines()
    return {line.split()[0] for line in listed if "/_services/" not in line}


def test_with_keys_a_call_and_an_event_cross(net: tuple[Hosts, Path], tmp_path: Path) -> None:
    hosts, keys = net
    robot_key = str(keys / "robot")  # the robot's own certificate, of the fleet's CA
    zenoh = ["--transport", "zenoh", "--naming", NAMING, "-MNC", "robot", "--keys", robot_key]
    server = start(hosts, "robot", [EXAMPLE, *zenoh, "ExampleA"], tmp_path / "example.err")
    ready(server, tmp_path / "example.err")
    assert probe(hosts, NAMING, "call", "robot/ExampleA", "5").strip() == "OK"

    channel = start(hosts, "robot", [str(TESTS / "procs" / "channel_host.py"), *zenoh, "Events"],
                    tmp_path / "channel.err")  # fmt: skip
    ready(channel, tmp_path / "channel.err")
    printer = hosts.popen(
        "base",
        str(TESTS / "procs" / "event_printer.py"),
        "--transport",
        "zenoh",
        "--naming",
        NAMING,
        "-MNC",
        "base",
        "robot/Events",
        stderr=tmp_path / "printer.err",
    )  # fmt: skip  (the base: the fleet's key)
    ready(printer, tmp_path / "printer.err")
    supplier = [str(TESTS / "procs" / "event_supplier.py"), *zenoh, "Events", "30", "20"]
    pushed = start(hosts, "robot", supplier, tmp_path / "supplier.err")
    assert pushed.wait(60) == 0, (tmp_path / "supplier.err").read_text()
    assert printer.stdout is not None
    seqs = [json.loads(printer.stdout.readline())["seq"] for _ in range(30)]
    assert seqs == list(range(seqs[0], seqs[0] + 30))
    hosts.kill([printer, pushed, channel, server])


def test_without_a_key_no_entry_and_no_name(net: tuple[Hosts, Path], tmp_path: Path) -> None:
    hosts, keys = net
    home = str(tmp_path / "home")  # no default key there
    zenoh = ["--transport", "zenoh", "--naming", NAMING, "-MNC", "intruder"]
    # No key at all, no --insecure: the intruder's service (the manual's ExampleA) stops at
    # start-up, in one line.
    example_a = str(TESTS.parent / "services" / "exampleA.py")
    keyless = start(hosts, "intruder", [example_a, *zenoh], tmp_path / "keyless.err",
                    MIRO_KEYS="", HOME=home)  # fmt: skip
    assert keyless.wait(60) == 2
    said = (tmp_path / "keyless.err").read_text().strip()
    assert "Traceback" not in said and len(said.splitlines()) == 1, said
    assert "talks to 10.83.0.1, beyond this machine, over Zenoh" in said
    assert "--keys FILE" in said and "--insecure" in said
    # In the clear, or with another fleet's key: the router refuses the session, and the
    # server waits for a router that will have it.
    refused = {
        "plain": start(hosts, "intruder", [EXAMPLE, *zenoh, "--insecure", "Plain"],
                       tmp_path / "plain.err", MIRO_KEYS="", HOME=home),
        "other": start(hosts, "intruder", [EXAMPLE, *zenoh, "--keys", str(keys / "other"),
                       "Other"], tmp_path / "other.err"),
    }  # fmt: skip
    for why, proc in refused.items():
        waiting(tmp_path / f"{why}.err")
        assert proc.poll() is None, (tmp_path / f"{why}.err").read_text()
    assert "at tcp/10.83.0.1:2809" in (tmp_path / "plain.err").read_text()
    assert "at tls/10.83.0.1:2809" in (tmp_path / "other.err").read_text()
    # A robot with the key gets in meanwhile; the intruders have bound nothing.
    welcome = start(hosts, "robot", [EXAMPLE, "--transport", "zenoh", "--naming", NAMING,
                    "-MNC", "robot", "Welcome"], tmp_path / "welcome.err")  # fmt: skip
    ready(welcome, tmp_path / "welcome.err")
    bound = names(hosts)
    assert "robot/Welcome" in bound
    assert not {n for n in bound if n.startswith("intruder/")}, bound
    for why, proc in refused.items():  # still waiting, never READY
        assert proc.poll() is None, (tmp_path / f"{why}.err").read_text()
    hosts.kill([*refused.values(), welcome])


def test_with_insecure_on_both_sides_it_works(net: tuple[Hosts, Path], tmp_path: Path) -> None:
    hosts, _ = net
    router = hosts.popen(
        "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--insecure", "--endpoint", OPEN,
        "--log-file", "none", stderr=tmp_path / "naming.err",
    )  # fmt: skip
    assert router.stdout is not None
    line = router.stdout.readline()
    assert "--insecure: in the clear, open to anyone who can reach it" in line, line
    warned = (tmp_path / "naming.err").read_text()
    assert "--insecure: the key" in warned and "is not used" in warned
    zenoh = ["--transport", "zenoh", "--naming", OPEN, "-MNC", "robot", "--insecure"]
    server = start(hosts, "robot", [EXAMPLE, *zenoh, "Open"], tmp_path / "open.err",
                   MIRO_KEYS="", HOME=str(tmp_path / "home"))  # fmt: skip
    ready(server, tmp_path / "open.err")
    assert (
        "--insecure: talking to the naming service at 10.83.0.1"
        in (tmp_path / "open.err").read_text()
    )
    assert probe(hosts, OPEN, "call", "robot/Open", "5", "--insecure").strip() == "OK"
    hosts.kill([server, router])
