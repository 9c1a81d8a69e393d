"""Benchmark: robots on the Zenoh backbone that find the base's router by multicast DNS, against
robots told its address, between network namespaces (tests/netns.py; needs root).

    sudo python bench/bench_discovery_zenoh.py [--robots 3] [--repeats 5]

The base runs `miro naming --zenoh` (announced: transport/naming/discovery.py) with the fleet's
key, so every link is mutual TLS. Each run starts one server per robot namespace
(`tests/procs/named_example.py`, its own naming context, ExampleA and ExampleB) at once, and a
lister in the base's namespace (a Zenoh client asking the registry every 20 ms) reports when
all of their names are visible; then the servers are killed and the names seen gone. Runs
alternate: found (no address: they browse, as `naming_for` does) and given (`--naming`).
Printed: each way's median seconds from the start of the servers until the base sees every
name, with the spread (min-max), the ratio found/given, and the load average. Issue 26's
target: every robot's names visible at the base within 2 s when found by mDNS.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]

from netns import Hosts, network  # noqa: E402

NAMED = str(ROOT / "tests" / "procs" / "named_example.py")
LISTER = f"""
import sys, time
sys.path[:0] = [{str(ROOT / "generated")!r}, {str(ROOT)!r}]
from miro_gen import Client
client = Client(["lister", "--transport", "zenoh", "--naming", sys.argv[1], "-MNC", "base"])
print("READY", flush=True)
for line in sys.stdin:
    want = int(line)
    while len([e for e in client.naming.entries("robot")]) != want:
        time.sleep(0.02)
    print(time.monotonic(), flush=True)
"""


def run_once(hosts: Hosts, lister: subprocess.Popen[str], robots: int, naming: str | None) -> float:
    """Seconds from the start of one server per robot until the base lists all their names."""
    assert lister.stdin is not None and lister.stdout is not None
    given = ["--naming", naming] if naming else []
    start = time.monotonic()
    argv = ["--transport", "zenoh", *given, "ExampleA", "ExampleB"]
    servers = [
        hosts.popen(f"robot{r}", NAMED, *argv, "-MNC", f"robot{r}", stderr=Path(os.devnull))
        for r in range(1, robots + 1)
    ]
    lister.stdin.write(f"{2 * robots}\n")
    lister.stdin.flush()
    seen = float(lister.stdout.readline())
    hosts.kill(servers)
    lister.stdin.write("0\n")
    lister.stdin.flush()
    lister.stdout.readline()
    return seen - start


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--robots", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    addresses = {"base": "10.86.0.1"} | {
        f"robot{r}": f"10.86.0.{r + 1}" for r in range(1, args.robots + 1)
    }
    naming = f"tcp://{addresses['base']}:2809"
    for hosts in network(addresses, tag="-bd"):
        router = hosts.popen(
            "base", "-m", "miro_gen.cli.main", "naming", "--zenoh", "--endpoint", naming,
            "--log-file", "none", "-MLL", "5",
        )  # fmt: skip
        assert router.stdout is not None
        for line in router.stdout:
            if "announced as" in line:
                break
        lister = subprocess.Popen(
            ["ip", "netns", "exec", hosts.ns("base"), sys.executable, "-c", LISTER, naming],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=hosts.env,
        )  # fmt: skip
        hosts.procs.append(lister)
        assert lister.stdout is not None and lister.stdout.readline().strip() == "READY"
        times: dict[str, list[float]] = {"found by mDNS": [], "address given": []}
        for _ in range(args.repeats):
            times["found by mDNS"].append(run_once(hosts, lister, args.robots, None))
            times["address given"].append(run_once(hosts, lister, args.robots, naming))
        load = os.getloadavg()
        print(f"{args.robots} robots x 2 names, Zenoh over mutual TLS, {args.repeats} repeats")
        for way, seconds in times.items():
            print(
                f"  {way:14}  median {statistics.median(seconds):.2f} s  "
                f"(min {min(seconds):.2f}, max {max(seconds):.2f})"
            )
        ratio = statistics.median(times["found by mDNS"]) / statistics.median(
            times["address given"]
        )
        print(f"  found/given {ratio:.2f}x; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
