"""Benchmark: a simulated fleet on the Zenoh backbone, on loopback: how long until the base sees
every robot's names, and what the router (`miro naming --zenoh`) costs.

    python bench/bench_fleet_zenoh.py [--robots 20] [--names 5]

Each robot is one process (`tests/procs/named_example.py`, its own naming context) serving
`--names` objects, each bound under its own name; all start at once. The base is this process,
a Zenoh client listing the names every 20 ms. Printed: the time from the start of the robots
until the base sees all of their names, the router process's CPU seconds over that time and
its resident memory at the end, and the load average. Issue 26 asked for 20 robots of five
services each as processes (100 processes); on a shared 2-core machine this runs one process
per robot with five objects, which binds the same number of names through as many sessions
as robots.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]
os.environ.setdefault("MIRO_DISCOVERY", "0")

from loopback import free_port, rss_mb, service_env  # noqa: E402

from miro_gen import Client  # noqa: E402

NAMED = str(ROOT / "tests" / "procs" / "named_example.py")


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--robots", type=int, default=20)
    ap.add_argument("--names", type=int, default=5)
    args = ap.parse_args()
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    env = service_env()
    router = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", endpoint,
         "--log-file", "none"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
    )  # fmt: skip
    assert router.stdout is not None
    router.stdout.readline()
    base = Client(["base", "--transport", "zenoh", "--naming", endpoint, "-MNC", "base"])
    robots: list[subprocess.Popen[str]] = []
    expected = {f"robot{r}/Object{n}" for r in range(args.robots) for n in range(args.names)}
    try:
        cpu0 = cpu_seconds(router.pid)
        start = time.monotonic()
        for r in range(args.robots):
            robots.append(subprocess.Popen(
                [sys.executable, NAMED, "--transport", "zenoh", "--naming", endpoint,
                 "-MNC", f"robot{r}", *(f"Object{n}" for n in range(args.names))],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True, env=env,
            ))  # fmt: skip
        while True:
            seen = {e.name for e in base.naming.entries("robot")}
            if expected <= seen:
                break
            if time.monotonic() - start > 300:
                print(f"gave up: {len(expected & seen)} of {len(expected)} names seen")
                return 1
            time.sleep(0.02)
        took = time.monotonic() - start
        cpu = cpu_seconds(router.pid) - cpu0
        load = os.getloadavg()
        print(f"{args.robots} robots x {args.names} names: the base saw all {len(expected)} "
              f"after {took:.2f} s")  # fmt: skip
        print(f"router (miro naming --zenoh): {cpu:.2f} CPU s meanwhile, "
              f"{rss_mb(router.pid):.1f} MiB resident")  # fmt: skip
        print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    finally:
        base.close()
        for p in robots:
            p.kill()
        for p in robots:
            p.wait()
        router.kill()
        router.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
