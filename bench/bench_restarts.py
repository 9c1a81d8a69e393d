"""Benchmark: how soon a name is resolvable again after a restart, and how soon a call to a
killed server fails (issue 33), this checkout against a baseline, in the same run.

    python bench/bench_restarts.py --baseline DIR [--repeats 5] [--restarts 4]

DIR is a checkout of the code before (`git archive COMMIT | tar -x -C DIR`). For each tree,
interleaved, `--repeats` times, with `--restarts` restarts per repeat, on loopback:

* `server`: a server (tests/procs/named_example.py, lease 3 s) killed with SIGKILL and started
  again at once: seconds from the new process's start to its name resolving to its new
  endpoint, and the same less its own start-up (a server started where nobody held the name);
  target: resolvable within 0.5 s of its start;
* `launch`: the same server run by `miro launch` (restart at once): seconds from the SIGKILL to
  its name resolving to the new endpoint;
* `naming`: the naming service killed and started again on its port: seconds from its first
  line ("naming service at ...") to the server's name resolving;
* `call`: a call pending on the server when it is killed: seconds from the SIGKILL to the
  call's failure (and its kind: never TIMEOUT), then the server restarted: seconds from its
  READY to the same stub's first call that succeeds.

Times come from CLOCK_MONOTONIC, shared by the processes of a machine: each probe runs the
tree's own code, in a process of its own started before the measurement. Prints medians with
min-max, the ratios ours / baseline, and the load average.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
LEASE = "3"

# Polls `name` until it resolves to an endpoint other than `old` ("-": any); prints the time.
WAIT_MOVED = """
import sys, time, zmq
from miro_gen.transport.rpc.invoker import ZmqInvoker
from miro_gen.transport.naming.client import NamingClient
naming = NamingClient(ZmqInvoker(zmq.Context()), sys.argv[1], "bench")
print("READY", flush=True)
old = sys.stdin.readline().strip()
while True:
    try:
        endpoint = naming.registry.resolve(sys.argv[2]).endpoint
        if endpoint != old:
            break
    except Exception:
        pass
    time.sleep(0.002)
print(time.monotonic(), endpoint, flush=True)
"""

# A pending call on r/A's old stub: prints CALLING, then when it fails its time and kind; then,
# told NEXT, calls the same stub until a call succeeds and prints that time.
PENDING_CALL = """
import sys, threading, time
import Miro
from miro_gen import Client
c = Client(["bench", "--naming", sys.argv[1]])
stub = c.resolve_name("r/A", Miro.Example)
def pending():
    try:
        stub.setData(-30.0, 0.0)
        print(time.monotonic(), "ok", flush=True)
    except Exception as e:
        print(time.monotonic(), type(e).__name__, flush=True)
t = threading.Thread(target=pending)
t.start()
time.sleep(0.3)
print("CALLING", flush=True)
t.join()
sys.stdin.readline()
while True:
    try:
        stub.getData()
        break
    except Exception:
        time.sleep(0.002)
print(time.monotonic(), flush=True)
"""


class Tree:
    """A source tree: its processes run its own code."""

    def __init__(self, label: str, root: Path) -> None:
        self.label = label
        self.root = root
        self.env = dict(
            os.environ,
            PYTHONPATH=os.pathsep.join([str(root / "generated"), str(root)]),
            MIRO_TEST_LEASE=LEASE,
            XDG_STATE_HOME=tempfile.mkdtemp(prefix="bench-restarts-"),
        )

    def popen(self, *argv: str, stdin: int | None = None) -> subprocess.Popen[str]:
        return subprocess.Popen(
            [sys.executable, *argv],
            stdin=stdin,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=self.env,
            cwd=str(self.root),
        )

    def script(self, code: str, *args: str) -> subprocess.Popen[str]:
        return self.popen("-c", textwrap.dedent(code), *args, stdin=subprocess.PIPE)

    def naming(self, port: int) -> subprocess.Popen[str]:
        endpoint = f"tcp://127.0.0.1:{port}"
        p = self.popen("-m", "miro_gen.cli.main", "naming", "--endpoint", endpoint)
        assert p.stdout is not None and p.stdout.readline().startswith("naming service at")
        return p

    def server(self, port: int) -> tuple[subprocess.Popen[str], float]:
        """named_example.py binding r/A; the time it started."""
        start = time.monotonic()
        p = self.popen(
            str(self.root / "tests" / "procs" / "named_example.py"),
            "--naming",
            f"tcp://127.0.0.1:{port}",
            "-MNC",
            "r",
            "A",
        )
        return p, start

    def wait_moved(self, port: int, old: str) -> subprocess.Popen[str]:
        probe = self.script(WAIT_MOVED, f"tcp://127.0.0.1:{port}", "r/A")
        assert line(probe) == "READY"
        assert probe.stdin is not None
        probe.stdin.write(old + "\n")
        probe.stdin.flush()
        return probe


def line(p: subprocess.Popen[str]) -> str:
    assert p.stdout is not None
    return p.stdout.readline().strip()


def end(*procs: subprocess.Popen[str]) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait(30)


def moved(probe: subprocess.Popen[str]) -> tuple[float, str]:
    when, endpoint = line(probe).split()
    probe.wait(30)
    return float(when), endpoint


# ---- the scenarios -----------------------------------------------------------------------------


def server_restarts(tree: Tree, restarts: int) -> tuple[list[float], list[float]]:
    """Seconds from a restarted server's start to its name resolving to it, and its start-up
    alone (a server with no predecessor)."""
    port = free_port()
    naming = tree.naming(port)
    probe = tree.wait_moved(port, "-")  # started first: its own start-up is not counted
    server, start = tree.server(port)
    first, endpoint = moved(probe)
    alone = first - start
    took = []
    for _ in range(restarts):
        probe = tree.wait_moved(port, endpoint)
        server.kill()
        server.wait(30)
        server, start = tree.server(port)
        when, endpoint = moved(probe)
        took.append(when - start)
    end(server, naming)
    return took, [alone]


def launch_restarts(tree: Tree, restarts: int) -> list[float]:
    """Seconds from the SIGKILL of a service under `miro launch` to its name resolving to the
    new run."""
    port = free_port()
    folder = Path(tempfile.mkdtemp(prefix="bench-launch-"))
    example = tree.root / "tests" / "procs" / "named_example.py"
    (folder / "robot.toml").write_text(
        textwrap.dedent(
            f"""
            [launch]
            context = "r"
            [naming]
            endpoint = "tcp://127.0.0.1:{port}"
            announce = false
            [services.victim]
            run = "{example}"
            args = ["A"]
            restart = "always"
            restart_delay = 0.1
            restart_delay_max = 0.1
            restart_limit = 1000
            """
        )
    )
    launch = tree.popen("-m", "miro_gen.cli.main", "launch", str(folder / "robot.toml"))
    pid = 0
    while True:
        text = line(launch)
        if "victim started, pid" in text:
            pid = int(text.split("pid")[1].split()[0])
            break
    probe = tree.wait_moved(port, "-")
    _, endpoint = moved(probe)
    took = []
    for _ in range(restarts):
        probe = tree.wait_moved(port, endpoint)
        killed = time.monotonic()
        os.kill(pid, signal.SIGKILL)
        while True:
            text = line(launch)
            if "victim started, pid" in text:
                pid = int(text.split("pid")[1].split()[0])
                break
        when, endpoint = moved(probe)
        took.append(when - killed)
    launch.send_signal(signal.SIGINT)
    launch.wait(60)
    shutil.rmtree(folder, ignore_errors=True)
    return took


def naming_restarts(tree: Tree, restarts: int) -> list[float]:
    """Seconds from a restarted naming service's first line to the server's name resolving."""
    port = free_port()
    naming = tree.naming(port)
    server, _ = tree.server(port)
    moved(tree.wait_moved(port, "-"))  # bound
    took = []
    for _ in range(restarts):
        time.sleep(1.0)  # a renewal or two
        naming.kill()
        naming.wait(30)
        probe = tree.script(WAIT_MOVED, f"tcp://127.0.0.1:{port}", "r/A")
        assert line(probe) == "READY"
        assert probe.stdin is not None
        probe.stdin.write("-\n")
        probe.stdin.flush()
        naming = tree.naming(port)
        up = time.monotonic()  # it said it serves (the probe may have heard it first: 0)
        when, _ = moved(probe)
        took.append(max(0.0, when - up))
    end(server, naming)
    return took


def pending_calls(tree: Tree, restarts: int) -> tuple[list[float], list[float], list[str]]:
    """Seconds from a SIGKILL to the pending call's failure, from the restarted server's READY
    to the old stub's first successful call, and the failures' kinds."""
    port = free_port()
    naming = tree.naming(port)
    server, _ = tree.server(port)
    assert line(server) == "READY"
    failed, next_ok, kinds = [], [], []
    for _ in range(restarts):
        caller = tree.script(PENDING_CALL, f"tcp://127.0.0.1:{port}")
        assert line(caller) == "CALLING"
        killed = time.monotonic()
        server.kill()
        server.wait(30)
        when, kind = line(caller).split()
        failed.append(float(when) - killed)
        kinds.append(kind)
        server, _ = tree.server(port)
        assert line(server) == "READY"
        ready = time.monotonic()
        assert caller.stdin is not None
        caller.stdin.write("NEXT\n")
        caller.stdin.flush()
        next_ok.append(float(line(caller)) - ready)
        caller.wait(30)
    end(server, naming)
    return failed, next_ok, kinds


# ---- the report --------------------------------------------------------------------------------


def summary(values: list[float]) -> str:
    return f"{statistics.median(values):6.3f} ({min(values):.3f}-{max(values):.3f})"


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--baseline", type=Path, help="a checkout of the code before")
    ap.add_argument("--repeats", type=int, default=5, help="interleaved repeats (default 5)")
    ap.add_argument("--restarts", type=int, default=4, help="restarts per repeat (default 4)")
    args = ap.parse_args()
    trees = [Tree("ours", ROOT)]
    if args.baseline is not None:
        trees.append(Tree("baseline", args.baseline.resolve()))
    rows: dict[tuple[str, str], list[float]] = {}
    kinds: dict[str, list[str]] = {t.label: [] for t in trees}
    loads = []
    for repeat in range(args.repeats):
        for tree in trees:
            took, alone = server_restarts(tree, args.restarts)
            rows.setdefault((tree.label, "server: start to resolvable"), []).extend(took)
            rows.setdefault((tree.label, "server: its own start-up"), []).extend(alone)
            rows.setdefault((tree.label, "launch: kill to resolvable"), []).extend(
                launch_restarts(tree, args.restarts)
            )
            rows.setdefault((tree.label, "naming: up to resolvable"), []).extend(
                naming_restarts(tree, args.restarts)
            )
            failed, next_ok, kind = pending_calls(tree, args.restarts)
            rows.setdefault((tree.label, "call: kill to failure"), []).extend(failed)
            rows.setdefault((tree.label, "call: READY to next call ok"), []).extend(next_ok)
            kinds[tree.label] += kind
        loads.append(os.getloadavg()[0])
        print(f"repeat {repeat + 1} of {args.repeats} done, load {loads[-1]:.1f}", flush=True)
    print(f"\nseconds, median (min-max) of {args.repeats} x {args.restarts}; "
          f"load average {min(loads):.1f}-{max(loads):.1f}")  # fmt: skip
    names = list(dict.fromkeys(row for _, row in rows))
    header = f"{'':32} {'ours':>22}"
    if len(trees) > 1:
        header += f" {'baseline':>22} {'ours/base':>9}"
    print(header)
    for name in names:
        ours = rows[("ours", name)]
        text = f"{name:32} {summary(ours):>22}"
        if ("baseline", name) in rows:
            base = rows[("baseline", name)]
            ratio = statistics.median(ours) / statistics.median(base)
            text += f" {summary(base):>22} {ratio:9.2f}"
        print(text)
    for label, found in kinds.items():
        counted = {k: found.count(k) for k in sorted(set(found))}
        print(f"pending calls' failures, {label}: {counted}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
