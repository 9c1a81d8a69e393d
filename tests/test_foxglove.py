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

import pytest
from eventlog_helpers import start_recorder, stop
from loopback import NamingProcess, service_env
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


def test_foxglove_decodes_every_recorded_message(tmp_path: Path) -> None:
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
    decoded = subprocess.run(
        ["node", str(FOXGLOVE / "decode.mjs"), str(log)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=FOXGLOVE,
    )
    assert decoded.returncode == 0, decoded.stderr
    got = [json.loads(line) for line in decoded.stdout.splitlines()]
    assert len(sent) == 6 and len(got) == len(sent)
    assert {(g["topic"], g["schema"]) for g in got} == {("robot1/Scan", "FoxTest::Scan")}
    for n, (g, s) in enumerate(zip(got, sent, strict=True)):
        s["big"] = str(s["big"])  # a long long is a BigInt in JavaScript (decode.mjs: a string)
        assert g["message"] == s, f"message {n} differs"
