"""The live tools on a robot whose types this machine does not have: a service publishes `Reading`
events on a channel of its own and serves `Lab::Store` (tests/procs/lab_service.py), compiled
into a folder the tools' processes do not see. `miro echo` finds the channel and decodes with
the schema the service gives, long sequences and byte strings are abridged unless asked for
whole, and a reader that goes away ends a tool quietly."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
import yaml
from eventlog_helpers import PROCS
from loopback import NamingProcess, service_env
from miro_cli import run_miro_idl

LAB_IDL = """\
module Lab {
  struct Reading { long n; sequence<octet> blob; sequence<float> ranges; };
  interface Store {
    Reading latest();
    sequence<long> numbers(in long count);
  };
};
"""


@dataclass
class Lab:
    naming: str
    env: dict[str, str]  # the tools': this checkout's generated code, not Lab's

    def miro(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", *args, "--naming", self.naming],
            capture_output=True, text=True, env=self.env, timeout=timeout,
        )  # fmt: skip


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Lab]:
    folder = tmp_path_factory.mktemp("lab")
    (folder / "Lab.idl").write_text(LAB_IDL)
    done = run_miro_idl("-o", str(folder / "generated"), str(folder / "Lab.idl"))
    assert done.returncode == 0, done.stderr
    naming = NamingProcess()
    service = subprocess.Popen(
        [sys.executable, str(PROCS / "lab_service.py"), str(folder / "generated"),
         "--naming", naming.endpoint, "-MNC", "lab"],
        stdout=subprocess.PIPE, text=True, env=service_env(),
    )  # fmt: skip
    try:
        assert service.stdout is not None and service.stdout.readline() == "READY\n"
        yield Lab(naming.endpoint, service_env(MIRO_CACHE=str(folder / "cache")))
    finally:
        service.terminate()
        service.wait(30)
        naming.stop()


READING = re.compile(r"^\d\d:\d\d:\d\d\.\d{6} lab/Reading #\d+ (?P<value>.*)$")


def test_echo_finds_the_suppliers_channel_and_decodes_with_their_schema(lab: Lab) -> None:
    done = lab.miro("echo", "Reading", "-n", "2")  # no --channel: lab/Sensors, not EventChannel
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 2, done.stdout + done.stderr
    for line in lines:
        m = READING.match(line)
        assert m is not None, line
        assert re.fullmatch(
            r"Reading\(n=\d+, blob=<1024 bytes: 00 01 02 03 04 05 06 07 08 09 \.\.\.>, "
            r"ranges=<1081 items: (0\.25, ){10}\.\.\.>\)",
            m["value"],
        ), m["value"]
    short = lab.miro("echo", "lab/Reading", "-n", "1", "-l", "2").stdout
    assert "blob=<1024 bytes: 00 01 ...>, ranges=<1081 items: 0.25, 0.25, ...>" in short
    whole = lab.miro("echo", "lab/Reading", "-n", "1", "--full-length").stdout
    assert f"blob={bytes(range(256)) * 4!r}, ranges=array('f', [{', '.join(['0.25'] * 1081)}])" in (
        whole
    )


def test_call_abridges_long_sequences_unless_asked_for_whole(lab: Lab) -> None:
    done = lab.miro("call", "lab/Store", "latest")
    assert done.returncode == 0, done.stderr
    assert yaml.safe_load(done.stdout) == {
        "n": 7,
        "blob": "<1024 bytes: 00 01 02 03 04 05 06 07 08 09 ...>",
        "ranges": "<1081 items: " + "0.5, " * 10 + "...>",
    }
    assert len(done.stdout.splitlines()) == 3
    whole = yaml.safe_load(lab.miro("call", "lab/Store", "latest", "-f").stdout)
    assert whole["blob"] == list(range(256)) * 4 and whole["ranges"] == [0.5] * 1081
    as_json = json.loads(lab.miro("call", "lab/Store", "latest", "--json").stdout)
    assert as_json["ranges"] == [0.5] * 1081  # machines get it whole
    assert lab.miro("call", "lab/Store", "numbers", "3").stdout == "- 0\n- 1\n- 2\n"


def test_a_reader_that_goes_away_ends_the_call_quietly(lab: Lab) -> None:
    """`miro call ... | head`: the reader closes the pipe long before the output ends."""
    call = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "call", "lab/Store", "numbers", "300000",
         "--json", "--naming", lab.naming],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=lab.env,
    )  # fmt: skip
    assert call.stdout is not None and call.stderr is not None
    assert call.stdout.read(10) == b"[0, 1, 2, "
    call.stdout.close()
    err = call.stderr.read().decode()
    assert call.wait(60) == 0, err
    assert "Traceback" not in err and "Exception ignored" not in err, err


def test_pub_waits_for_the_listening_consumer_so_that_count_n_delivers_n(lab: Lab) -> None:
    """`miro echo` listens; `miro pub --rate 5 --count 3` waits for its subscription before the
    first event (ros2 topic pub's --wait-matching-subscriptions), so all three arrive."""
    echo = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "echo", "tester/Reading", "-n", "3",
         "--channel", "lab/Sensors", "--naming", lab.naming],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=lab.env,
    )  # fmt: skip
    try:
        pub = lab.miro(
            "pub", "tester/Reading", "{n: -1, blob: ab, ranges: [1, 2]}", "--rate", "5",
            "--count", "3",
        )  # fmt: skip
        assert pub.returncode == 0, pub.stderr
        assert pub.stdout.splitlines() == [f"published tester/Reading #{n}" for n in range(3)]
        out, err = echo.communicate(timeout=60)
    finally:
        if echo.poll() is None:
            echo.kill()
            echo.wait()
    assert echo.returncode == 0, err
    assert [line.split()[1:3] for line in out.splitlines()] == [
        ["tester/Reading", f"#{n}"] for n in range(3)
    ]
