"""Who binds which names at the Zenoh backbone's registry under access control per robot
(`miro naming --zenoh --per-robot`), between network namespaces with real TLS keys: a base
holding the fleet's key and robots each with a certificate of the fleet's CA (`miro keys new
robotN --ca fleet`). A robot binds through the registry's key of its certificate, which the
router lets only that certificate ask (transport/zenoh/access.py), so the registry knows which
robot binds: a robot binds only in its own context, the base anywhere, quotas count per robot,
and a certificate the router denies gets a clear error instead of a bare timeout."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from loopback import service_env
from netns import Hosts, network
from repo_paths import TESTS

from miro_gen.transport.tlsfiles import base_of

zenoh = pytest.importorskip("zenoh")

from miro_gen.transport.zenoh import keys  # noqa: E402
from miro_gen.transport.zenoh.access import access_control  # noqa: E402

ADDRESSES = {
    "base": "10.86.0.1",
    "robot1": "10.86.0.2",
    "robot2": "10.86.0.3",
    "robot3": "10.86.0.4",
}
NAMING = f"tcp://{ADDRESSES['base']}:2809"
ZENOH = ("--transport", "zenoh", "--naming", NAMING)
PROCS = TESTS / "procs"
NAMING_LOG: list[Path] = []  # the router's stderr (the fixture's)
BINDER = str(PROCS / "zenoh_binder.py")
QUOTA = 3  # names per principal
ROBOTS = ("robot1", "robot2", "robot3", "robot4")  # the certificates --per-robot lists
STRANGER = "robot5"  # a certificate of the fleet's CA that --per-robot does not list


@given(st.text(min_size=1), st.text(min_size=1))
def test_a_registry_key_is_reached_only_by_its_owners_rule(owner: str, other: str) -> None:
    """What the router's rules rely on, checked with Zenoh's own key expressions: a robot's
    registry key is a valid key that `**` (a robot's rule for querying anything) does not
    include, the router's queryable does, and another owner's rule does not."""
    key = keys.registry_key(owner)
    assert keys.registry_owner(key) == owner
    endpoint = keys.naming_endpoint(owner)
    assert keys.is_naming(endpoint) and keys.route_key(endpoint, "%/0") == key
    assert not zenoh.KeyExpr("**").includes(zenoh.KeyExpr(key))
    assert zenoh.KeyExpr(keys.REGISTRY_KEYS).includes(zenoh.KeyExpr(key))
    if other != owner:
        assert not zenoh.KeyExpr(keys.registry_key(other)).includes(zenoh.KeyExpr(key))


def test_only_a_robots_own_registry_key_is_allowed_to_it() -> None:
    acl = access_control("fleet", ["robot1", "robot2"])
    asks = {
        r["id"]: r["key_exprs"]
        for r in acl["rules"]
        if "query" in r["messages"] and "ingress" in r["flows"]
    }
    assert asks["r1-bind"] == ["miro/@registry/robot2"]
    assert "miro/@registry/*" in asks["fleet"]
    assert not [k for rule, ks in asks.items() if rule.startswith("r0") for k in ks
                if "@registry" in k and k != "miro/@registry/robot1"]  # fmt: skip
    for endpoint in ("zenoh/naming@", "zenoh/naming@%", "zenoh/naming@a/b", "zenoh/naming@*"):
        assert not keys.is_naming(endpoint)
    assert keys.naming_endpoint("") == keys.NAMING_ENDPOINT


def robot_env(hosts: Hosts, robot: str) -> dict[str, str]:
    """The environment of a process holding `robot`'s key instead of the fleet's."""
    return {**hosts.env, "MIRO_KEYS": str(Path(base_of(hosts.env["MIRO_KEYS"])).parent / robot)}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Hosts]:
    """The namespaces, the robots' keys, the router with access per robot and a quota of
    QUOTA names per principal, and ExampleA served by robot1 in its own context."""
    for hosts in network(ADDRESSES, tag="-own"):
        fleet_key = base_of(hosts.env["MIRO_KEYS"])
        for robot in (*ROBOTS, STRANGER):
            made = subprocess.run(
                [sys.executable, "-m", "miro_gen.cli.main", "keys", "new",
                 str(Path(fleet_key).parent / robot), "--ca", fleet_key],
                capture_output=True, text=True, env=service_env(), timeout=60,
            )  # fmt: skip
            assert made.returncode == 0, made.stderr
        logs = tmp_path_factory.mktemp("owners")
        NAMING_LOG.append(logs / "naming.err")
        naming = hosts.popen(
            "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", NAMING,
            "--log-file", "none", "--per-robot", ",".join(ROBOTS), "--quota", str(QUOTA),
            stderr=logs / "naming.err",
        )  # fmt: skip
        assert naming.stdout is not None
        line = naming.stdout.readline()
        assert "access per robot" in line, line + (logs / "naming.err").read_text()
        server = hosts.popen(
            "robot1", str(PROCS / "named_example.py"), *ZENOH, "-MNC", "robot1", "ExampleA",
            stderr=logs / "robot1.err", env=robot_env(hosts, "robot1"),
        )  # fmt: skip
        assert server.stdout is not None
        assert server.stdout.readline().strip() == "READY", (logs / "robot1.err").read_text()
        yield hosts


def binder(hosts: Hosts, host: str, key: str | None, *args: str) -> list[str]:
    """The lines of zenoh_binder.py run at `host` with `key`'s certificate (None: the
    fleet's)."""
    env = hosts.env if key is None else robot_env(hosts, key)
    done = hosts.run(host, BINDER, NAMING, *args, env=env)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout.splitlines()


def test_a_robot_binds_only_in_its_own_context(fleet: Hosts) -> None:
    before = binder(fleet, "robot2", "robot2", "resolve", "robot1/ExampleA")
    assert before[0].startswith("ENTRY robot1/ExampleA zenoh/robot1/"), before
    # robot2's certificate: robot1's bound name, a free name there, and one of its own
    said = binder(fleet, "robot2", "robot2", "bind", "robot1/ExampleA", "robot1/Free", "robot2/Own")
    assert said == [
        "REFUSED robot1/ExampleA NO_PERMISSION: the certificate robot2 binds names only in its "
        "own context (robot2/...), not robot1/ExampleA (`miro naming --per-robot`; run it with "
        "-MNC robot2)",
        "REFUSED robot1/Free NO_PERMISSION: the certificate robot2 binds names only in its own "
        "context (robot2/...), not robot1/Free (`miro naming --per-robot`; run it with -MNC "
        "robot2)",
        "BOUND robot2/Own",
    ], said
    after = binder(fleet, "base", None, "resolve", "robot1/ExampleA", "robot1/Free", "robot2/Own")
    assert after == [before[0], "NOTFOUND robot1/Free", "ENTRY robot2/Own zenoh/%/binder"], after
    # robot1's certificate still binds in robot1's context
    assert binder(fleet, "robot1", "robot1", "bind", "robot1/Second") == ["BOUND robot1/Second"]
    log = NAMING_LOG[-1].read_text()  # the router said it (the first of a burst: rate-limited)
    assert "refused to bind robot1/ExampleA for cert:robot2: the certificate" in log, log


def test_the_base_binds_anywhere(fleet: Hosts) -> None:
    said = binder(fleet, "base", None, "bind", "robot3/FromBase", "AtTheRoot")
    assert said == ["BOUND robot3/FromBase", "BOUND AtTheRoot"], said


def test_quotas_count_per_robot(fleet: Hosts) -> None:
    names = [f"robot3/n{i}" for i in range(QUOTA + 1)]
    said = binder(fleet, "robot3", "robot3", "bind", *names)
    assert [line.split(" ", 2)[:2] for line in said] == [
        *(["BOUND", n] for n in names[:QUOTA]),
        ["REFUSED", names[QUOTA]],
    ], said
    assert "NO_RESOURCES" in said[QUOTA], said
    # another robot's names count against its own quota, not robot3's
    others = [f"robot4/n{i}" for i in range(QUOTA)]
    assert binder(fleet, "robot2", "robot4", "bind", *others) == [f"BOUND {n}" for n in others]


def test_a_denied_certificate_is_told_why(fleet: Hosts) -> None:
    """A certificate of the CA that --per-robot does not list: the router drops everything it
    asks. Its bind and its look-up fail with the likely cause, not a bare timeout, and a server
    holding it stops saying so instead of waiting for a naming service that answers others."""
    said = binder(fleet, "robot3", STRANGER, "bind", f"{STRANGER}/X")
    hint = (
        "the router's access control (`miro naming --zenoh --per-robot`) may deny the "
        f"certificate {STRANGER} the key miro/@registry/{STRANGER}: is {STRANGER} listed there?"
    )
    assert said[0].startswith(f"REFUSED {STRANGER}/X TIMEOUT: bind_as: no reply from the naming")
    assert said[0].endswith(hint), said
    found = fleet.run(
        "robot3", str(TESTS / "procs" / "zenoh_probe.py"), NAMING, "list", "robot1/",
        env=robot_env(fleet, STRANGER),
    )  # fmt: skip
    assert found.returncode != 0
    last = found.stderr.strip().splitlines()[-1]
    assert f"may deny the certificate {STRANGER} the key miro/call/%/" in last, found.stderr
    served = fleet.run(
        "robot3", str(PROCS / "named_example.py"), *ZENOH, "-MNC", STRANGER, "ExampleA",
        env=robot_env(fleet, STRANGER),
    )  # fmt: skip
    assert served.returncode != 0 and "READY" not in served.stdout
    lines = served.stderr.strip().splitlines()  # (its error's line ends what it says)
    assert lines, served.stderr
    assert f"may deny the certificate {STRANGER} the key miro/@registry/{STRANGER}" in lines[-1], (
        served.stderr
    )


def test_a_robot_started_before_its_router_waits_and_binds(fleet: Hosts, tmp_path: Path) -> None:
    """Silence from a router that is still starting is not taken for a denial: robot1's server,
    started first, binds once a second router (with access per robot) is up."""
    naming = f"tcp://{ADDRESSES['base']}:2810"
    server = fleet.popen(
        "robot1", str(PROCS / "named_example.py"), "--transport", "zenoh", "--naming", naming,
        "-MNC", "robot1", "Early", stderr=tmp_path / "early.err", env=robot_env(fleet, "robot1"),
    )  # fmt: skip
    router = fleet.popen(
        "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", naming,
        "--log-file", "none", "--per-robot", "robot1", stderr=tmp_path / "router.err",
    )  # fmt: skip
    assert server.stdout is not None
    assert server.stdout.readline().strip() == "READY", (tmp_path / "early.err").read_text()
    probe = fleet.run(
        "base", BINDER, naming, "resolve", "robot1/Early", env=fleet.env
    )  # fmt: skip
    assert probe.stdout.startswith("ENTRY robot1/Early zenoh/robot1/"), probe.stderr
    fleet.kill([server, router])
