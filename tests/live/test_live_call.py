"""The live tools against a robot brought up with `miro launch`: the manual's examples and the GPS
driver on a simulated receiver. `miro list`, `miro call`, `miro pub` and `miro param` are run as
a user runs them, each a process of its own, with the interfaces compiled from what the
services say (into a cache of the test's own)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import free_port, service_env
from miro_cli import REPO

from miro_gen.testing import ServiceProcess

SERVICES = REPO / "services"


class Robot:
    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.naming = f"tcp://127.0.0.1:{free_port()}"
        self.cache = folder / "cache"
        (folder / "robot.toml").write_text(
            textwrap.dedent(
                f"""
                [launch]
                context = "robot1"

                [naming]
                endpoint = "{self.naming}"
                channels = ["EventChannel"]

                [services.sim]
                command = ["miro", "sim", "nmea", "--link", "{folder}/gps0", "--rate", "5"]
                ready = "NMEA on"

                [services.gps]
                run = "{SERVICES}/gps"
                after = ["sim"]
                parameters.Gps.Gps = {{ Device = "{folder}/gps0" }}

                [services.exampleA]
                run = "{SERVICES}/exampleA.py"

                [services.exampleC]
                run = "{SERVICES}/exampleC.py"
                args = ["0.2"]

                [services.exampleD]
                run = "{SERVICES}/exampleD.py"
                after = ["ExampleEventChannel"]
                """
            )
        )
        self.launch = ServiceProcess(
            "miro_gen.cli.main", "launch", str(folder / "robot.toml"), cwd=REPO
        )

    def miro(self, *args: str, stdin: str | None = None) -> subprocess.CompletedProcess[str]:
        env = service_env(MIRO_CACHE=str(self.cache))
        return subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *args, "--naming", self.naming],
            capture_output=True,
            text=True,
            env=env,
            input=stdin,
            timeout=60,
        )


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Robot]:
    r = Robot(tmp_path_factory.mktemp("robot"))
    try:
        r.launch.wait_for("| gps: reading")
        r.launch.wait_for("| ExampleD listens")
        r.launch.wait_for("| ExampleA is ready")
        yield r
    finally:
        assert r.launch.stop() == 0, r.launch.output


def test_list_shows_services_objects_operations_events_and_parameters(robot: Robot) -> None:
    done = robot.miro("list")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "robot1/exampleA  (pid " in out
    assert "    robot1/ExampleA  IDL:Miro/Example:1.0" in out
    assert "      void setData(in double a, in double b)" in out
    assert "      Miro::GpsDataIDL getWaitData() raises (Miro::ETimeOut)" in out
    assert "    robot1/ExampleEvent  Miro::ExampleEventIDL  on robot1/ExampleEventChannel" in out
    assert "    */ExampleEvent  on robot1/ExampleEventChannel" in out
    assert "    Gps/Gps  Miro::GpsParameters  (from " in out
    assert "event channels:\n  EventChannel  at tcp://127.0.0.1:" in out


def test_call_sets_and_gets_with_the_services_own_interface(robot: Robot) -> None:
    done = robot.miro("call", "robot1/ExampleA", "setData", "1.5", "2")
    assert (done.returncode, done.stdout, done.stderr) == (0, "", "")
    done = robot.miro("call", "robot1/ExampleA", "getData")
    assert done.stdout == "a: 2.5\nb: 3.0\n", done.stderr  # ExampleA returns a + 1, b + 1
    done = robot.miro("call", "robot1/ExampleA", "setData", "{a: 3, b: 4}")
    assert done.returncode == 0
    assert robot.miro("call", "robot1/ExampleA", "getData", "--json").stdout == (
        '{"a": 4.0, "b": 5.0}\n'
    )
    compiled = list(robot.cache.glob("*/py/Miro/schema_idl.py"))
    assert compiled, "the stub was not compiled from the service's schema"


def test_call_says_what_is_wrong_in_one_line(robot: Robot) -> None:
    cases = {
        ("setData", "x", "2"): "miro call: setData: a: expected a number, not 'x'\n",
        ("setData", "2"): (
            "miro call: setData takes 2 arguments: void setData(in double a, in double b)\n"
        ),
        ("nope",): (
            "miro call: IDL:Miro/Example:1.0 has no operation nope (it has: setData, getData)\n"
        ),
    }
    for args, message in cases.items():
        done = robot.miro("call", "robot1/ExampleA", *args)
        assert (done.returncode, done.stderr) == (1, message)
    done = robot.miro("call", "robot1/Nothing", "getData")
    assert done.stderr == "miro call: robot1/Nothing is not bound in the naming service\n"


def test_pub_publishes_an_event_the_consumer_receives(robot: Robot) -> None:
    done = robot.miro("pub", "robot1/ExampleEvent", "{counter: 99, data: {a: 1, b: 2}}")
    assert done.returncode == 0, done.stderr
    assert done.stdout == "published robot1/ExampleEvent #0\n"
    robot.launch.wait_for("| Received ExampleEvent #99 from robot1: a = 1, b = 2")


def test_param_set_is_checked_applied_and_used_by_the_driver(robot: Robot, tmp_path: Path) -> None:
    assert robot.miro("param", "get", "gps", "WaitTimeout").stdout == "5, 0\n"
    bad = robot.miro("param", "set", "gps", "Gps.WaitTimeout", "soon")
    assert bad.returncode == 1
    assert bad.stderr.startswith("miro param: <set>:1: error: Gps.WaitTimeout: expected")
    assert robot.miro("param", "get", "gps", "Gps.WaitTimeout").stdout == "5, 0\n"
    assert robot.miro("call", "robot1/Gps", "getWaitData").returncode == 0
    done = robot.miro("param", "set", "gps", "Gps.WaitTimeout", "0, 1")  # one microsecond
    assert done.stdout == "Gps/Gps.WaitTimeout = 0, 1\n", done.stderr
    late = robot.miro("call", "robot1/Gps", "getWaitData")
    assert late.returncode == 1
    assert late.stderr.startswith("robot1/Gps getWaitData raised IDL:Miro/ETimeOut:1.0"), (
        late.stderr
    )
    dumped = tmp_path / "gps.xml"
    assert robot.miro("param", "dump", "gps", "-o", str(dumped)).returncode == 0
    from Miro.GpsParameters import GpsParameters

    from miro_gen.params import read_parameters

    params = GpsParameters()
    assert read_parameters(params, "Gps", config_file=str(dumped))
    assert params.waitTimeout.total_seconds() == pytest.approx(1e-6)
    assert params.device == str(robot.folder / "gps0")
    robot.miro("param", "set", "gps", "Gps.WaitTimeout", "5")


def test_without_a_naming_service_the_tools_say_so() -> None:
    env = dict(service_env(), MIRO_NAMING=f"tcp://127.0.0.1:{free_port()}")
    env.pop("MIRO_CACHE", None)
    done = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "list"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        cwd=os.getcwd(),
    )
    assert done.returncode == 1
    assert done.stderr.startswith("miro list: the naming service at tcp://127.0.0.1:")
    assert "Traceback" not in done.stderr


def test_bash_completes_names_operations_topics_and_parameters(robot: Robot) -> None:
    script = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "completion", "bash"],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=60,
    ).stdout
    assert "complete -o filenames -F _miro_complete miro" in script

    def tab(*words: str) -> list[str]:
        """What bash offers at a Tab after `words` (the last one being typed)."""
        line = " ".join(f"'{w}'" for w in words)
        done = subprocess.run(
            [
                "bash",
                "-c",
                f"{script}\nCOMP_WORDS=({line}); COMP_CWORD={len(words) - 1}; _miro_complete; "
                'printf "%s\\n" "${COMPREPLY[@]}"',
            ],
            capture_output=True,
            text=True,
            env=dict(
                service_env(MIRO_CACHE=str(robot.cache), MIRO_NAMING=robot.naming),
                PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}",
            ),
            timeout=60,
        )
        return done.stdout.split()

    assert tab("miro", "pa") == ["param", "params"]
    assert "robot1/ExampleA" in tab("miro", "call", "")
    assert tab("miro", "call", "robot1/ExampleA", "") == ["getData", "setData"]
    assert tab("miro", "param", "set", "gps", "Gps.W") == ["Gps.WaitTimeout"]
    assert "robot1/ExampleEvent" in tab("miro", "pub", "")
    assert tab("miro", "call", "--ti") == ["--timeout"]
