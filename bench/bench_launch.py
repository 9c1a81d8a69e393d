"""Benchmark: what `miro launch` adds to bringing services up, against starting them by hand.

    python bench/bench_launch.py [--services N] [--runs R] [--check]

Both ways start a naming service on a free port and then N copies of the manual's ExampleA
(each in a naming context of its own), and are timed from the first process started until
every ExampleA has printed `ExampleA is ready`:

* by hand: as a shell script would, `miro naming` in the background, then, once it says where
  it serves, the N services, each `python services/exampleA.py --naming ... -MNC robotK`;
* launch: `miro launch robot.toml` with the same N services in its file (the launch starts,
  reads and checks the file, checks that generated/ is fresh, starts the naming service, waits
  for it to answer, starts the services and copies their output).

The overhead per service is (launch - by hand) / N; the target (issue 19) is at most 0.3 s.
Runs alternate between the two ways; the medians are reported. The machine is shared: expect
noise. `--check` exits 1 when the target is missed.

    python bench/bench_launch.py --killed [--grace G] [--runs R] [--check]

How long the services of a launch outlive it (issue 33): a launch with a service that ignores
SIGTERM and one whose children (one in its process group, one in a group of its own that
ignores SIGTERM too) is stopped either by Ctrl-C (SIGINT: the launch stops them itself) or by
SIGKILL (its watcher stops them), alternately; each run is timed from the signal until no
process of the services is left (polled every 10 ms). The target is at most grace + 1 s after
SIGKILL; `--check` exits 1 when the median misses it.
"""

from __future__ import annotations

import argparse
import os
import queue
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
SERVICES = ROOT / "services"
TARGET = 0.3  # seconds per service
READY = "ExampleA is ready"


def env() -> dict[str, str]:
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(ROOT / "generated"), str(ROOT)])
    e["PYTHONUNBUFFERED"] = "1"
    return e


def wait_lines(procs: list[subprocess.Popen[str]], text: str, count: int) -> None:
    """Read the processes' output (a thread each) until `count` lines contain `text`."""
    lines: queue.SimpleQueue[str | None] = queue.SimpleQueue()

    def read(proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    for proc in procs:
        threading.Thread(target=read, args=(proc,), daemon=True).start()
    seen, ended = 0, 0
    while seen < count:
        line = lines.get(timeout=60)
        if line is None:
            ended += 1
            if ended == len(procs):
                raise RuntimeError("every process ended")
        elif text in line:
            seen += 1


def stop(procs: list[subprocess.Popen[str]]) -> None:
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def by_hand(n: int) -> float:
    port = free_port()
    start = time.perf_counter()
    naming = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint",
         f"tcp://127.0.0.1:{port}"],
        stdout=subprocess.PIPE, text=True, env=env(),
    )  # fmt: skip
    assert naming.stdout is not None
    naming.stdout.readline()  # "naming service at ...": it serves
    services = []
    for k in range(n):
        argv = [sys.executable, "-u", str(SERVICES / "exampleA.py")]
        argv += ["--naming", f"tcp://127.0.0.1:{port}", "-MNC", f"robot{k}"]
        services.append(subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, env=env()))
    wait_lines(services, READY, n)
    took = time.perf_counter() - start
    stop([*services, naming])
    return took


def launched(n: int, folder: Path) -> float:
    path = folder / "robot.toml"
    lines = ["[naming]", f'endpoint = "tcp://127.0.0.1:{free_port()}"', ""]
    for k in range(n):
        lines += [
            f"[services.a{k}]",
            f'run = "{SERVICES / "exampleA.py"}"',
            f'context = "robot{k}"',
            "",
        ]
    path.write_text("\n".join(lines))
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "launch", str(path), "--no-status"],
        stdout=subprocess.PIPE, text=True, env=env(),
    )  # fmt: skip
    wait_lines([proc], READY, n)
    took = time.perf_counter() - start
    stop([proc])
    return took


STUBBORN = """
import os, signal, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)
print(f"pids {os.getpid()}", flush=True)
time.sleep(600)
"""
FORKER = """
import os, signal, subprocess, time
child = subprocess.Popen(["sleep", "600"])
hidden = subprocess.Popen(["sleep", "601"], process_group=0,
                          preexec_fn=lambda: signal.signal(signal.SIGTERM, signal.SIG_IGN))
print(f"pids {os.getpid()} {child.pid} {hidden.pid}", flush=True)
time.sleep(600)
"""


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def stopped(folder: Path, grace: float, sig: int) -> float:
    """Seconds from `sig` to the launch until none of its services' processes is left."""
    (folder / "stubborn.py").write_text(STUBBORN)
    (folder / "forker.py").write_text(FORKER)
    (folder / "robot.toml").write_text(textwrap.dedent(f"""
        [launch]
        grace = {grace}
        [services.stubborn]
        run = "stubborn.py"
        [services.forker]
        run = "forker.py"
        """))  # fmt: skip
    proc = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "launch", str(folder / "robot.toml"),
         "--no-status", "--no-build"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env(),
    )  # fmt: skip
    assert proc.stdout is not None
    pids: list[int] = []
    for line in proc.stdout:
        if "| pids " in line:
            pids += [int(p) for p in line.split("| pids ")[1].split()]
            if len(pids) == 4:
                break
    start = time.perf_counter()
    proc.send_signal(sig)
    while any(alive(p) for p in pids):
        if time.perf_counter() - start > 60:
            raise RuntimeError(f"still running after 60 s: {[p for p in pids if alive(p)]}")
        time.sleep(0.01)
    took = time.perf_counter() - start
    proc.wait(30)
    proc.stdout.read()  # until the watcher, which shares it, has ended
    return took


def killed(ns: argparse.Namespace) -> int:
    orderly, outright = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(ns.runs):
            orderly.append(stopped(Path(tmp), ns.grace, signal.SIGINT))
            outright.append(stopped(Path(tmp), ns.grace, signal.SIGKILL))
    o, k = statistics.median(orderly), statistics.median(outright)
    print(f"grace {ns.grace:g} s, {ns.runs} runs each, load average {os.getloadavg()[0]:.2f}")
    for name, runs, med in (("Ctrl-C", orderly, o), ("kill -9", outright, k)):
        print(f"  {name:8} {med:6.3f} s  (spread {min(runs):.3f}-{max(runs):.3f})  until none left")
    print(f"  kill -9 / Ctrl-C: {k / o:.2f}x; after kill -9: grace {k - ns.grace:+.3f} s "
          "(target: at most grace + 1 s)")  # fmt: skip
    return 1 if ns.check and k > ns.grace + 1 else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--services", type=int, default=5, help="services to start (default 5)")
    p.add_argument("--runs", type=int, default=5, help="runs of each way (default 5)")
    p.add_argument("--check", action="store_true", help="exit 1 when the target is missed")
    p.add_argument(
        "--killed", action="store_true", help="time the stop after Ctrl-C and after kill -9"
    )
    p.add_argument("--grace", type=float, default=2.0, help="--killed: the grace (default 2 s)")
    ns = p.parse_args()
    if ns.killed:
        return killed(ns)
    hand, launch = [], []
    with tempfile.TemporaryDirectory() as tmp:
        launched(1, Path(tmp))  # warm the caches (generated/ freshness stamp, imports)
        for _ in range(ns.runs):
            hand.append(by_hand(ns.services))
            launch.append(launched(ns.services, Path(tmp)))
    h, lt = statistics.median(hand), statistics.median(launch)
    per = (lt - h) / ns.services
    print(f"{ns.services} services, {ns.runs} runs each (medians; a shared machine: noisy)")
    print(f"  by hand      {h:6.3f} s   (runs: {', '.join(f'{t:.2f}' for t in hand)})")
    print(f"  miro launch  {lt:6.3f} s   (runs: {', '.join(f'{t:.2f}' for t in launch)})")
    print(f"  launch / by hand: {lt / h:.2f}x; added per service: {per:+.3f} s (target <= "
          f"{TARGET} s)")  # fmt: skip
    return 1 if ns.check and per > TARGET else 0


if __name__ == "__main__":
    sys.exit(main())
