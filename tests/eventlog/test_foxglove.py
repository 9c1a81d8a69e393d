"""Logs open in Foxglove: its own Node libraries decode every message of a recorded file.

A supplier process pushes FoxTest::Scan events (structs, sequences, strings, enums, unions,
arrays, nested types; tests/foxglove/FoxTest.idl) that `miro log record` writes; then
tests/foxglove/decode.mjs reads the file with @mcap/core, parses the schema with
@foxglove/omgidl-parser and decodes each message with @foxglove/omgidl-serialization. Every
message must equal what was sent. Needs node and the npm packages of tests/foxglove
(`.ci/run` installs them with `npm ci`).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from eventlog_helpers import start_recorder, stop
from loopback import NamingProcess, run_miro, service_env
from miro_cli import REPO, run_miro_idl

FOXGLOVE = REPO / "tests" / "foxglove"


def _skip_reason() -> str | None:
    if shutil.which("node") is None:
        return "node is not installed (Foxglove's libraries are JavaScript)"
    for package in ("@mcap/core", "@foxglove/omgidl-parser", "@foxglove/omgidl-serialization"):
        if not (FOXGLOVE / "node_modules" / package).is_dir():
            return f"{package} is not installed: run `npm ci` in tests/foxglove (.ci/run does)"
    return None


pytestmark = pytest.mark.skipif(_skip_reason() is not None, reason=str(_skip_reason()))


@pytest.fixture(scope="module")
def fox_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, Any]]]:
    """A log `miro log record` wrote of FoxTest::Scan events, and the events as sent."""
    tmp_path = tmp_path_factory.mktemp("fox")
    generated = tmp_path / "gen"
    compiled = run_miro_idl("-o", str(generated), str(FOXGLOVE / "FoxTest.idl"))
    assert compiled.returncode == 0, compiled.stderr
    env = service_env()
    env["PYTHONPATH"] = os.pathsep.join([str(generated), env["PYTHONPATH"]])
    naming = NamingProcess(options=("--channel", "EventChannel"))
    try:
        log = tmp_path / "fox.mcap"
        rec = start_recorder(naming.endpoint, log, "*/Scan", env=env)
        supplier = subprocess.run(
            [
                sys.executable,
                str(REPO / "tests" / "procs" / "fox_supplier.py"),
                "--naming",
                naming.endpoint,
                "-MNC",
                "robot1",
                "EventChannel",
            ],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
        assert supplier.returncode == 0, supplier.stderr
        _, err = stop(rec, signal.SIGINT)
        assert rec.returncode == 0, err
    finally:
        naming.stop()
    sent = [json.loads(line) for line in supplier.stdout.splitlines() if line.startswith("{")]
    for s in sent:
        s["big"] = str(s["big"])  # a long long is a BigInt in JavaScript (decode.mjs: a string)
    return log, sent


def foxglove_decode(path: Path) -> list[dict[str, Any]]:
    decoded = subprocess.run(
        ["node", str(FOXGLOVE / "decode.mjs"), str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=FOXGLOVE,
    )
    assert decoded.returncode == 0, decoded.stderr
    return [json.loads(line) for line in decoded.stdout.splitlines()]


def test_foxglove_decodes_every_recorded_message(
    fox_log: tuple[Path, list[dict[str, Any]]],
) -> None:
    log, sent = fox_log
    got = foxglove_decode(log)
    assert len(sent) == 6 and len(got) == len(sent)
    assert {(g["topic"], g["schema"]) for g in got} == {("robot1/Scan", "FoxTest::Scan")}
    for n, (g, s) in enumerate(zip(got, sent, strict=True)):
        assert g["message"] == s, f"message {n} differs"


def test_foxglove_decodes_logs_cut_and_merged(
    fox_log: tuple[Path, list[dict[str, Any]]], tmp_path: Path
) -> None:
    """`miro log cut` and `miro log merge` write files Foxglove's libraries read as they
    read the recorder's."""
    log, sent = fox_log
    times = [int(g["logTime"]) for g in foxglove_decode(log)]
    cut = tmp_path / "cut.mcap"
    start, end = (times[1] - times[0]) / 1e9, (times[4] - times[0]) / 1e9
    done = run_miro(
        "log", "cut", str(log), str(cut), "--start", f"{start:.9f}", "--end", f"{end:.9f}"
    )
    assert done.returncode == 0, done.stderr
    got = foxglove_decode(cut)
    assert [g["message"] for g in got] == sent[1:5]
    merged = tmp_path / "merged.mcap"
    done = run_miro("log", "merge", str(log), str(cut), "-o", str(merged))
    assert done.returncode == 0, done.stderr
    got = foxglove_decode(merged)
    assert {(g["topic"], g["schema"]) for g in got} == {("robot1/Scan", "FoxTest::Scan")}
    by_time = sorted(
        [*zip(times, sent, strict=True), *zip(times[1:5], sent[1:5], strict=True)],
        key=lambda ts: ts[0],
    )
    assert [g["message"] for g in got] == [s for _, s in by_time]
