"""`miro launch`: the launch file's checks (`file:line: error:`), start order, restart policies,
and Ctrl-C stopping everything, with real processes (small scripts written by the tests, and
the manual's examples)."""

from __future__ import annotations

import os
import re
import signal
import sys
import textwrap
from pathlib import Path

import pytest
from loopback import alive, eventually
from miro_cli import REPO

from miro_gen.cli.launch import launch_main
from miro_gen.launch.spec import LaunchError, read_launch_file
from miro_gen.launch.supervisor import naming_service, plan
from miro_gen.testing import ServiceProcess


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(text).lstrip())
    return path


def errors(tmp_path: Path, text: str) -> list[str]:
    path = write(tmp_path, "robot.toml", text)
    with pytest.raises(LaunchError) as caught:
        read_launch_file(path)
    return [str(d).replace(str(path), "robot.toml") for d in caught.value.diagnostics]


def launch(folder: Path, *args: str) -> ServiceProcess:
    """`miro launch` of `folder/robot.toml`, as a user starts it (no terminal: no table)."""
    return ServiceProcess(
        "miro_gen.cli.main", "launch", str(folder / "robot.toml"), *args, cwd=REPO
    )


def said(proc: ServiceProcess) -> list[str]:
    """Its lines with the labels' padding taken out: `b | text`."""
    return [" ".join(line.split()) for line in proc.lines]


def started_pids(proc: ServiceProcess) -> list[int]:
    return [int(re.search(r"started, pid (\d+)", t)[1]) for t in proc.lines if "started, pid" in t]


# ---- the file ------------------------------------------------------------------------------------


def test_a_syntax_error_says_line_and_column(tmp_path: Path) -> None:
    got = errors(tmp_path, '[services.a]\nrun = "a.py"\nrestart = on-failure\n')
    assert got == ["robot.toml:3:11: error: Invalid value"]
    got = errors(tmp_path, '[services.a]\nrun = "a.py"\nargs = [1,\n')
    assert got == ["robot.toml:3: error: Invalid value (at the end of the file)"]


def test_semantic_errors_point_at_the_line_of_the_key(tmp_path: Path) -> None:
    write(tmp_path, "a.py", "print('a')\n")
    got = errors(
        tmp_path,
        """
        [launch]
        grace = "long"

        [services.a]
        run = "a.py"
        restart = "on-failur"
        restrat_limit = 3

        [services.b]
        run = "missing.py"
        after = ["c"]

        [services.c]
        command = ["echo", "{nmae}"]
        after = ["b"]
        """,
    )
    assert "robot.toml:2: error: grace must be a number of seconds, not 'long'" in got
    assert (
        "robot.toml:6: error: restart must be never, on-failure or always, not 'on-failur' "
        "(did you mean 'on-failure'?)" in got
    )
    assert (
        "robot.toml:7: error: unknown key 'restrat_limit' in [services.a] "
        "(did you mean 'restart_limit'?)" in got
    )
    assert "robot.toml:10: error: missing.py: no such script or service folder" in got
    assert any(g.startswith("robot.toml:14: error: unknown placeholder {nmae}") for g in got)
    assert any("wait for each other in a circle: b -> c -> b" in g for g in got), got


def test_a_service_needs_one_thing_to_run(tmp_path: Path) -> None:
    got = errors(tmp_path, '[services.a]\nargs = ["x"]\n\n[services.b]\nrun = "x"\nmodule = "y"\n')
    assert got[0] == "robot.toml:1: error: [services.a] needs exactly one of run, module or " + (
        "command (none)"
    )
    assert got[1] == (
        "robot.toml:4: error: [services.b] needs exactly one of run, module or command "
        "(run and module)"
    )


def test_check_prints_the_plan_of_the_shipped_demo(capsys: pytest.CaptureFixture[str]) -> None:
    assert launch_main([str(REPO / "services" / "demo.toml"), "--check"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert "5 to start; naming service at tcp://127.0.0.1:" in lines[0]
    assert [line.split()[0] for line in lines[2:]] == [
        "naming",
        "exampleA",
        "exampleB",
        "exampleC",
        "exampleD",
    ]
    assert "ExampleA" in lines[4]


def test_check_shows_the_commands_with_their_placeholders_filled_in(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write(
        tmp_path,
        "robot.toml",
        '[naming]\nendpoint = "tcp://127.0.0.1:5999"\n\n[services.cam]\n'
        'command = ["cat", "{dir}/cam.cfg", "{name}", "{naming}", "{context}", "{{x}}"]\n'
        'context = "robot1"\n',
    )
    assert launch_main([str(path), "--check"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("cam "))
    assert row.endswith(f"cat {tmp_path}/cam.cfg cam tcp://127.0.0.1:5999 robot1 {{x}}"), row


def test_errors_in_the_file_exit_1_without_starting_anything(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write(tmp_path, "robot.toml", '[services.a]\ncommand = "true"\nrestart = 3\n')
    assert launch_main([str(path)]) == 1
    assert capsys.readouterr().err == (
        f"{path}:3: error: restart must be never, on-failure or always, not 3\n"
    )


def test_numbers_are_finite_and_in_range(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """TOML spells nan and inf: `grace = nan` would make Ctrl-C wait forever, `restart_delay =
    nan` never restart, `restart_delay = 0` restart a crashing service 24 times a second."""
    got = errors(
        tmp_path,
        """
        [launch]
        grace = nan

        [services.a]
        command = "true"
        restart_delay = nan
        restart_delay_max = -inf
        stable_after = 0

        [services.b]
        command = "true"
        restart_delay = 0
        restart_delay_max = inf
        """,
    )
    assert got == [
        "robot.toml:2: error: grace must be from 0 to 3600 seconds, not nan",
        "robot.toml:6: error: restart_delay must be from 0.1 to 3600 seconds, not nan",
        "robot.toml:7: error: restart_delay_max must be from 1 to 3600 seconds, not -inf",
        "robot.toml:8: error: stable_after must be from 1 to 86400 seconds, not 0",
        "robot.toml:12: error: restart_delay must be from 0.1 to 3600 seconds, not 0",
        "robot.toml:13: error: restart_delay_max must be from 1 to 3600 seconds, not inf",
    ]
    path = tmp_path / "robot.toml"
    assert launch_main([str(path)]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"{path}:2: error: grace must be from 0 to 3600 seconds, not nan"
    write(tmp_path, "robot.toml", '[launch]\ngrace = 1e400\n[services.a]\ncommand = "true"\n')
    assert launch_main([str(path)]) == 1
    assert capsys.readouterr().err == (
        f"{path}:2: error: grace must be from 0 to 3600 seconds, not inf\n"
    )


def test_the_floors_keep_a_crash_loop_slow(tmp_path: Path) -> None:
    """The smallest delays the file may give still double up to at least 1 s."""
    write(
        tmp_path,
        "robot.toml",
        """
        [services.a]
        command = "false"
        restart_delay = 0.1
        restart_delay_max = 1
        restart_limit = 100
        """,
    )
    (a,) = read_launch_file(tmp_path / "robot.toml").services
    assert [a.restart.backoff(n) for n in range(1, 7)] == [0.1, 0.2, 0.4, 0.8, 1.0, 1.0]


def test_the_naming_service_takes_the_restart_keys_of_a_service(tmp_path: Path) -> None:
    """[naming] restarts as a service does, with the same keys (not 'unknown key')."""
    write(
        tmp_path,
        "robot.toml",
        """
        [naming]
        restart = "on-failure"
        restart_delay = 0.2
        restart_delay_max = 2
        restart_limit = 3
        stable_after = 5

        [services.a]
        command = "true"
        """,
    )
    spec = read_launch_file(tmp_path / "robot.toml")
    assert spec.naming is not None
    policy = spec.naming.restart
    assert (policy.when, policy.delay, policy.delay_max, policy.limit, policy.stable_after) == (
        "on-failure",
        0.2,
        2.0,
        3,
        5.0,
    )


# ---- running ---------------------------------------------------------------------------------


def test_order_restarts_and_one_ctrl_c_stops_everything(tmp_path: Path) -> None:
    """b starts once a is ready; c fails twice and is restarted; d ignores SIGTERM and leaves a
    grandchild: after one SIGINT to the launch, none of their processes is left."""
    write(tmp_path, "a.py", "import time\nprint('a ready', flush=True)\ntime.sleep(600)\n")
    write(tmp_path, "b.py", "import time\nprint('b runs', flush=True)\ntime.sleep(600)\n")
    write(
        tmp_path,
        "c.py",
        """
        import os, sys, time
        runs = os.path.join(os.path.dirname(__file__), "c.runs")
        n = len(open(runs).read()) if os.path.exists(runs) else 0
        open(runs, "a").write("x")
        print(f"c run {n}", flush=True)
        if n < 2:
            sys.exit(3)
        time.sleep(600)
        """,
    )
    write(
        tmp_path,
        "d.py",
        """
        import signal, subprocess, time
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        child = subprocess.Popen(["sleep", "600"])
        print(f"d pids {__import__('os').getpid()} {child.pid}", flush=True)
        time.sleep(600)
        """,
    )
    write(
        tmp_path,
        "robot.toml",
        f"""
        [launch]
        grace = 1

        [services.a]
        run = "a.py"
        ready = "a ready"

        [services.b]
        run = "b.py"
        after = ["a"]

        [services.c]
        command = ["{sys.executable}", "-u", "c.py"]
        cwd = "."
        restart = "on-failure"
        restart_delay = 0.1

        [services.d]
        run = "d.py"
        """,
    )
    with launch(tmp_path) as proc:
        proc.wait_for("| b runs")
        lines = said(proc)
        assert next(i for i, t in enumerate(lines) if "a | a ready" in t) < next(
            i for i, t in enumerate(lines) if "launch | b started" in t
        )
        proc.wait_for("| c run 2")
        assert "launch | c exited with status 3; restart 1 of 5 in 0.1 s" in said(proc)
        assert "launch | c exited with status 3; restart 2 of 5 in 0.2 s" in said(proc)
        d_line = proc.wait_for("| d pids")[0]
        pids = [int(p) for p in d_line.split()[-2:]]
        started = started_pids(proc)
        assert proc.stop() == 0
        assert "launch | d did not stop within 1 s: killed" in said(proc)
        assert said(proc)[-1] == "launch | all stopped"
    assert not any("launch watcher" in t for t in proc.lines)  # it ended without a word
    for pid in [*pids, *started]:
        eventually(lambda pid=pid: not alive(pid))  # type: ignore[misc]


def test_a_required_service_that_cannot_stay_up_ends_the_launch_with_1(tmp_path: Path) -> None:
    write(tmp_path, "ok.py", "import time\ntime.sleep(600)\n")
    write(tmp_path, "bad.py", "import sys\nprint('bad', flush=True)\nsys.exit(4)\n")
    write(
        tmp_path,
        "robot.toml",
        """
        [services.ok]
        run = "ok.py"

        [services.bad]
        run = "bad.py"
        restart_delay = 0.1
        restart_limit = 2
        """,
    )
    with launch(tmp_path) as proc:
        assert proc.proc.wait(60) == 1
        proc.stop()
    out = "\n".join(said(proc))
    assert out.count("bad | bad") == 3
    assert "launch | bad exited with status 4 after 2 restarts; given up" in out
    assert "launch | stopped: bad could not stay up: it exited with status 4 after 2 restarts" in (
        out
    )


def test_services_that_end_well_end_the_launch_with_0(tmp_path: Path) -> None:
    write(tmp_path, "once.py", "print('done', flush=True)\n")
    write(
        tmp_path,
        "robot.toml",
        """
        [services.once]
        run = "once.py"

        [services.optional]
        command = "false"
        restart = "never"
        required = false
        """,
    )
    with launch(tmp_path) as proc:
        assert proc.proc.wait(60) == 0
    assert "launch | once exited with status 0" in said(proc)
    assert "launch | optional exited with status 1; given up" in said(proc)


def test_a_launch_killed_outright_leaves_no_process(tmp_path: Path) -> None:
    """SIGKILL gives the launch no chance to stop anything: its watcher stops the services in
    its place. One ignores SIGTERM; the other's children (one in its process group, one that
    moved to a group of its own and ignores SIGTERM) are not its direct children: after the
    grace period, none of them is left."""
    write(
        tmp_path,
        "stubborn.py",
        """
        import os, signal, time
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        print(f"stubborn pid {os.getpid()}", flush=True)
        time.sleep(600)
        """,
    )
    write(
        tmp_path,
        "forker.py",
        """
        import os, signal, subprocess, time
        child = subprocess.Popen(["sleep", "600"])
        hidden = subprocess.Popen(  # SIGTERM ignored in it, also after exec
            ["sleep", "601"],
            process_group=0,
            preexec_fn=lambda: signal.signal(signal.SIGTERM, signal.SIG_IGN),
        )
        print(f"forker pids {os.getpid()} {child.pid} {hidden.pid}", flush=True)
        time.sleep(600)
        """,
    )
    write(
        tmp_path,
        "robot.toml",
        """
        [launch]
        grace = 1

        [services.stubborn]
        run = "stubborn.py"
        ready = "stubborn pid"

        [services.forker]
        run = "forker.py"
        after = ["stubborn"]
        """,
    )
    with launch(tmp_path) as proc:
        stubborn = proc.wait_for("| stubborn pid", timeout=60)[0]
        forker = proc.wait_for("| forker pids", timeout=60)[0]
        pids = [int(stubborn.split()[-1]), *(int(p) for p in forker.split()[-3:])]
        assert all(alive(pid) for pid in pids)
        proc.proc.kill()
        proc.proc.wait(30)
        for pid in pids:
            eventually(lambda pid=pid: not alive(pid), 30)  # type: ignore[misc]
        proc.wait_for("process(es) left after 1 s: killed", timeout=30)
    (said_first,) = [t for t in proc.lines if t.startswith("launch watcher:")][:1]
    assert "ended without stopping its services" in said_first


def watcher_of(launch_pid: int) -> int | None:
    """The pid of the watcher of the launch `launch_pid` (None: none now)."""
    for entry in Path("/proc").iterdir():
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if (
            b"miro_gen.launch.tree" in argv
            and str(launch_pid).encode() in argv
            and alive(int(entry.name))
        ):
            return int(entry.name)
    return None


def test_a_watcher_that_ends_is_replaced(tmp_path: Path) -> None:
    """The watcher killed (the OOM killer, a careless pkill): the launch starts another and
    tells it everything, so a launch killed afterwards still leaves nothing."""
    forever = "import os, time\nprint('up', os.getpid(), flush=True)\ntime.sleep(600)\n"
    write(tmp_path, "forever.py", forever)
    write(tmp_path, "robot.toml", '[launch]\ngrace = 1\n[services.forever]\nrun = "forever.py"\n')
    with launch(tmp_path) as proc:
        pid = int(proc.wait_for("| up ", timeout=60)[0].split()[-1])
        eventually(lambda: watcher_of(proc.proc.pid) is not None, 30)
        first = watcher_of(proc.proc.pid)
        assert first is not None
        os.kill(first, signal.SIGKILL)
        proc.wait_for(f"the watcher (pid {first}) ended with -9; another started", timeout=30)
        # (a process's command line can be read only a moment after its start)
        eventually(lambda: watcher_of(proc.proc.pid) not in (None, first), 30)
        proc.proc.kill()
        proc.proc.wait(30)
        eventually(lambda: not alive(pid), 30)


def test_inline_parameters_become_the_services_document(tmp_path: Path) -> None:
    write(tmp_path, "show.py", "import sys\nprint(open(sys.argv[-1]).read(), flush=True)\n")
    write(
        tmp_path,
        "base.xml",
        '<config><section name="Gps"><parameter name="Gps">'
        '<parameter name="Device" value="/dev/ttyS0"/><parameter name="ObjectName" value="G"/>'
        "</parameter></section></config>",
    )
    write(
        tmp_path,
        "robot.toml",
        """
        [services.show]
        run = "show.py"
        params = "base.xml"
        parameters.Gps.Gps = { Device = "/tmp/gps0", TtyParams = { Baudrate = 9600 } }
        """,
    )
    with launch(tmp_path) as proc:
        assert proc.proc.wait(60) == 0
    out = proc.output
    assert '<parameter name="Device" value="/tmp/gps0"/>' in out
    assert '<parameter name="ObjectName" value="G"/>' in out
    assert '<parameter name="Baudrate" value="9600"/>' in out


def test_the_demo_launch_file_runs_the_manuals_examples() -> None:
    with ServiceProcess(
        "miro_gen.cli.main", "launch", str(REPO / "services" / "demo.toml"), cwd=REPO
    ) as proc:
        proc.wait_for("| Received ExampleEvent #", count=2)
        proc.wait_for("| Retrieved variables a and b are: 1 and 11")
        pids = started_pids(proc)
        proc.proc.send_signal(signal.SIGINT)
        assert proc.proc.wait(30) == 0
    for pid in pids:
        eventually(lambda pid=pid: not alive(pid))  # type: ignore[misc]


# ---- the backbone: transport = "zenoh" (docs/FLEET.md) -------------------------------------------


def test_the_transport_key_is_checked_with_one_line_errors(tmp_path: Path) -> None:
    write(tmp_path, "a.py", "print('a')\n")
    got = errors(
        tmp_path,
        """
        [launch]
        transport = "zenho"
        fleet_events = { EventChannel = ["Odometry", 3], "robot1/Events" = "*" }

        [services.a]
        run = "a.py"
        transport = 3
        fleet_events = { EventChannel = [] }
        """,
    )
    assert got == [
        "robot.toml:2: error: transport must be zmq or zenoh, not 'zenho' (did you mean 'zenoh'?)",
        "robot.toml:3: error: fleet_events.EventChannel must be a list of event types",
        "robot.toml:3: error: fleet_events: channel 'robot1/Events' cannot be shared: a name "
        "without / * ; = , or spaces",
        "robot.toml:7: error: transport must be zmq or zenoh, not 3",
        'robot.toml:8: error: fleet_events.EventChannel must name event types (or ["*"])',
    ]
    got = errors(
        tmp_path,
        """
        [launch]
        transport = "zenoh"

        [naming]
        insecure = "yes"

        [services.a]
        run = "a.py"
        transport = "zmq"
        """,
    )
    assert got == [
        "robot.toml:5: error: insecure must be true or false, not 'yes'",
        "robot.toml:9: error: transport 'zmq' is not the backbone of the naming service this "
        "file starts (zenoh: [launch] transport)",
    ]


def test_a_file_on_zenoh_starts_the_router_and_gives_its_services_the_backbone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write(
        tmp_path,
        "robot.toml",
        """
        [launch]
        transport = "zenoh"
        fleet_events = { E = ["T", "U"] }

        [naming]
        endpoint = "tcp://127.0.0.1:5998"

        [services.a]
        command = ["sh", "-c", "echo $MIRO_TRANSPORT"]

        [services.b]
        command = ["sh", "-c", "echo $MIRO_TRANSPORT"]
        transport = "zenoh"
        fleet_events = {}
        """,
    )
    spec = read_launch_file(path)
    assert spec.transport == "zenoh" and [s.transport for s in spec.services] == ["zenoh"] * 2
    assert [s.fleet_events for s in spec.services] == [{"E": frozenset({"T", "U"})}, {}]
    assert launch_main([str(path), "--check"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("naming "))
    assert "naming --endpoint tcp://127.0.0.1:5998 --zenoh" in row, row
    plain = write(tmp_path, "plain.toml", '[services.a]\ncommand = "true"\n')
    assert read_launch_file(plain).services[0].transport is None  # the environment's, or zmq


def test_the_zenoh_router_of_a_file_restricts_the_robots_it_names(tmp_path: Path) -> None:
    """`per_robot` in [naming]: the router's access control per robot (docs/FLEET.md;
    tests/transport/test_zenoh_acl.py shows it across namespaces)."""
    path = write(
        tmp_path,
        "fleet.toml",
        """
        [launch]
        transport = "zenoh"

        [naming]
        endpoint = "tcp://127.0.0.1:5997"
        per_robot = ["robot1", "robot2"]

        [services.a]
        command = "true"
        """,
    )
    argv = naming_service(read_launch_file(path)).argv
    assert argv[argv.index("--per-robot") + 1] == "robot1,robot2"


def test_the_manuals_examples_run_over_zenoh_from_a_launch_file(tmp_path: Path) -> None:
    """The demo's four services with `transport = "zenoh"`: `miro naming --zenoh` is started,
    the services bind and find each other through its router (a ZeroMQ process could not), and
    `after` waits for names in its registry."""
    services = REPO / "services"
    write(
        tmp_path,
        "robot.toml",
        f"""
        [launch]
        transport = "zenoh"

        [naming]
        endpoint = "tcp://127.0.0.1:*"

        [services.exampleA]
        run = "{services / "exampleA.py"}"

        [services.exampleB]
        run = "{services / "exampleB.py"}"
        args = ["--period", "0.2"]
        after = ["ExampleA"]

        [services.exampleC]
        run = "{services / "exampleC.py"}"
        args = ["0.2"]

        [services.exampleD]
        run = "{services / "exampleD.py"}"
        after = ["ExampleEventChannel"]
        """,
    )
    with launch(tmp_path) as proc:
        proc.wait_for("| Received ExampleEvent #", count=2)
        proc.wait_for("| Retrieved variables a and b are: 1 and 11")
        proc.proc.send_signal(signal.SIGINT)
        assert proc.proc.wait(30) == 0
    assert any("Zenoh router" in line for line in proc.lines), proc.lines


def test_a_zenoh_router_on_another_host_is_found_by_its_announcement(tmp_path: Path) -> None:
    """As a ZeroMQ naming service: the router of `miro naming --zenoh` is announced (multicast
    DNS, tests/transport/test_discovery_zenoh.py), so a host that is not told where it is looks
    for it."""
    path = write(
        tmp_path,
        "robot.toml",
        """
        [launch]
        transport = "zenoh"

        [hosts.base]
        [hosts.robot]

        [naming]
        host = "base"
        endpoint = "tcp://0.0.0.0:2809"

        [services.a]
        command = "true"
        host = "robot"
        """,
    )
    part = plan(read_launch_file(path), "robot")
    assert part.discover and part.naming_url is None
