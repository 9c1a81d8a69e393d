"""What the event-log tests share: the log tools and the test processes, run as a user does."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from loopback import service_env
from miro_cli import REPO

PROCS = REPO / "tests" / "procs"


def miro(*args: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    """`miro ARGS` from this checkout, in the background."""
    return subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env() if env is None else env,
    )


def proc(script: str, *args: str) -> subprocess.Popen[str]:
    """A test process of tests/procs, in the background."""
    return subprocess.Popen(
        [sys.executable, str(PROCS / script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=service_env(),
    )


def start_recorder(
    naming: str, path: Path, *topics: str, env: dict[str, str] | None = None
) -> subprocess.Popen[str]:
    """`miro log record`, returned once it has found its channel."""
    rec = miro("log", "record", "--naming", naming, "-o", str(path), *topics, env=env)
    assert rec.stderr is not None
    line = rec.stderr.readline()
    assert line.startswith("recording "), line
    return rec


def stop(p: subprocess.Popen[str], sig: int = signal.SIGINT) -> tuple[str, str]:
    p.send_signal(sig)
    out, err = p.communicate(timeout=20)
    return out, err


def supply(naming: str, count: int, *gaps_ms: int, context: str = "robot1") -> None:
    """Run tests/procs/event_supplier.py to its end: COUNT ExampleEvents from `context`."""
    sup = proc(
        "event_supplier.py",
        "--naming",
        naming,
        "-MNC",
        context,
        "EventChannel",
        str(count),
        *map(str, gaps_ms),
    )
    out, err = sup.communicate(timeout=60)
    assert sup.returncode == 0 and "DONE" in out, err


def read_events(stdout: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]


T0 = 1_700_000_000_000_000_000  # ns: the log time of the first event of the logs written here


def write_log(
    path: Path,
    events: list[tuple[str, int, int]],
    *,
    type_name: str = "ExampleEvent",
    chunk_every: int = 0,
    finish: bool = True,
) -> Path:
    """A log of ExampleEvents `(domain, counter, log time offset in ms)`, each ExampleEventIDL(
    counter, (counter, -counter)) with sequence number `counter`, stamped 1 ms before its log
    time; a chunk closed after every `chunk_every` events; without `finish` the file has no
    summary (as a recorder killed outright leaves it)."""
    import Miro

    from miro_gen.eventlog.writer import LogWriter
    from miro_gen.transport.events.frames import RawEvent

    h = Miro.ExampleEventIDL._type_hash
    writer = LogWriter(str(path))
    for n, (domain, counter, ms) in enumerate(events, 1):
        t = T0 + ms * 1_000_000
        payload = Miro.ExampleEventIDL(counter, Miro.ExampleStructIDL(float(counter), -counter))
        writer.write(
            [RawEvent(domain, type_name, h, 1, counter, t - 1_000_000, t, payload.serialize())], t
        )
        if chunk_every and n % chunk_every == 0:
            writer.flush()
    if finish:
        writer.finish()
    else:
        writer.flush()
        writer._file.close()
    return path
