"""Benchmark: an IIOP server's memory, threads and CPU under the floods of issue 33, this
checkout against a baseline, in the same run.

    python bench/bench_iiop_floods.py [--baseline DIR] [--only NAME ...] [--calls N]

Each flood attacks a fresh server process (`tests/giop_attacks.py`'s VICTIM: an `IIOPServer`
on 127.0.0.1 serving a Miro::Example) started from a source tree: this checkout and, with
`--baseline`, another one (a copy of the code before, e.g. `git archive COMMIT | tar -x -C
DIR`). While the flood is held, N pairs of legitimate calls (setData, getData, each pair on a
new connection, 10 s timeout) are made; then the server's peak resident memory (VmHWM) is
read. Floods:

* `big-requests`: 8 connections, each sending a 63 MiB Request all but its last byte;
* `fragments`: one connection sending 32 fragmented Requests of 16 MiB, none finished;
* `idle`: 1,100 connections that send nothing: the server's threads and descriptors once
  their number stays the same for 2 s;
* `emfile`: the same 1,100 connections to a server whose descriptor limit is 256, all but
  16 of them taken by other files: then the share of a CPU it uses for 3 s, and the calls
  answered;
* `cpp-calls`: no flood, then the `big-requests` one: the round trip of omniORB's C++ client
  (tests/corba/peer.cc, built as the tests build it) to the server, p50 of 5 x 2,000 calls.

The machine these numbers come from is shared: run it a few times and read the load average
printed with them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]

import giop_attacks as attack  # noqa: E402

MIB = 1 << 20


def _answered(port: int, calls: int) -> str:
    ok, failures = attack.calls_answered(port, calls)
    why = f" ({failures[0][:60]})" if failures else ""
    return f"calls answered {ok}/{calls}{why}"


def big_requests(root: Path, calls: int) -> str:
    v = attack.Victim(root)
    held = attack.hold_big_requests(v.port, 8, 63 * MIB)
    answered = _answered(v.port, calls)
    result = f"added {v.added_mib():6.0f} MiB, {answered}"
    attack.close_all(held)
    v.stop()
    return result


def fragments(root: Path, calls: int) -> str:
    v = attack.Victim(root)
    held = attack.hold_fragments(v.port, 32, 16 * MIB)
    answered = _answered(v.port, calls)
    closed = " (the server closed the connection)" if held.fileno() < 0 else ""
    result = f"added {v.added_mib():6.0f} MiB{closed}, {answered}"
    held.close()
    v.stop()
    return result


def idle(root: Path, calls: int) -> str:
    v = attack.Victim(root)
    held = attack.open_idle(v.port, 1100)
    fds = attack.settle(v.pid)
    threads = attack.status(v.pid, "Threads")
    answered = _answered(v.port, calls)
    attack.close_all(held)
    v.stop()
    return f"threads {threads:5}, descriptors {fds:5}, {answered}"


def emfile(root: Path, calls: int) -> str:
    v = attack.Victim(root, nofile=256, spare=16)
    held = attack.open_idle(v.port, 1100)
    attack.settle(v.pid)
    with attack.cpu_share(v.pid) as share:
        time.sleep(3)
    answered = _answered(v.port, calls)
    attack.close_all(held)
    v.stop()
    return f"CPU {share[0] * 100:5.1f}% of a core over 3 s, {answered}"


ECHO = """
import sys, threading
import Peer, Peer__POA
from corba_peers import echo_servant
from miro_gen.corba import IIOPInvoker, IIOPServer
from miro_gen.corba.ior import ior_from_ref
invoker = IIOPInvoker()
server = IIOPServer(invoker)
print(ior_from_ref(server.activate(echo_servant(Peer, Peer__POA), "Echo")).to_string(), flush=True)
threading.Event().wait()
"""


def cpp_calls(trees: list[tuple[str, Path]]) -> list[str]:
    """The round trip of omniORB's C++ client to the server of each tree (tests/corba/peer.cc's
    `bench`: nothing() on a worker, echo_text("hello") @nonblocking): 5 rounds of 2,000 calls,
    the trees' rounds interleaved, p50 of each round's p50; then again while 8 connections
    hold 63 MiB requests part-way at every server."""
    from corba_peers import build_peer, generate_python, missing_tools

    if missing_tools():
        return [f"skipped: needs {', '.join(missing_tools())}"]
    peer = build_peer()
    gen = Path(tempfile.mkdtemp(prefix="bench-iiop-floods-"))
    generate_python(gen)
    servers, iors = [], []
    for _, root in trees:
        path = [str(root / "generated"), str(root), str(gen), str(ROOT / "tests")]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(path))
        server = subprocess.Popen(
            [sys.executable, "-c", textwrap.dedent(ECHO)], stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, text=True, env=env,
        )  # fmt: skip
        assert server.stdout is not None
        servers.append(server)
        iors.append(server.stdout.readline().strip())

    def one_round(ior: str) -> tuple[float, float]:
        out = subprocess.run(
            [str(peer), "bench", ior, "2000"], capture_output=True, text=True, timeout=300
        ).stdout
        _, nothing, text = next(x for x in out.splitlines() if x.startswith("P50 ")).split()
        return float(nothing), float(text)

    def p50s() -> list[tuple[float, float]]:
        rounds: list[list[tuple[float, float]]] = [[] for _ in iors]
        for _ in range(5):
            for i, ior in enumerate(iors):
                rounds[i].append(one_round(ior))
        return [
            (statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs))
            for rs in rounds
        ]

    try:
        quiet = p50s()
        held = [attack.hold_big_requests(ior_port(ior), 8, 63 * MIB) for ior in iors]
        flooded = p50s()
        for h in held:
            attack.close_all(h)
    finally:
        for server in servers:
            server.kill()
            server.wait(10)
    return [
        f"p50 us: nothing() {q[0]:6.1f}, echo_text {q[1]:6.1f}; during the flood "
        f"{f[0]:6.1f}, {f[1]:6.1f}"
        for q, f in zip(quiet, flooded, strict=True)
    ]


def ior_port(ior: str) -> int:
    from miro_gen.corba.ior import IOR

    profile = IOR.from_string(ior).iiop_profile()
    assert profile is not None
    return profile.port


FLOODS: dict[str, Callable[[Path, int], str]] = {
    "big-requests": big_requests,
    "fragments": fragments,
    "idle": idle,
    "emfile": emfile,
}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--baseline", type=Path, help="another source tree to run the same floods on")
    p.add_argument(
        "--only", nargs="*", choices=[*sorted(FLOODS), "cpp-calls"], help="these floods only"
    )
    p.add_argument("--calls", type=int, default=5, help="legitimate call pairs per flood")
    ns = p.parse_args()
    trees = [("this checkout", ROOT)]
    if ns.baseline is not None:
        trees.append(("baseline", ns.baseline.resolve()))
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for name in ns.only or [*FLOODS, "cpp-calls"]:
        if name == "cpp-calls":
            for (label, _), result in zip(trees, cpp_calls(trees), strict=False):
                print(f"{name:13} {label:14} {result}", flush=True)
            continue
        for label, root in trees:
            started = time.monotonic()
            result = FLOODS[name](root, ns.calls)
            took = time.monotonic() - started
            print(f"{name:13} {label:14} {result}  ({took:.0f} s)", flush=True)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
