"""Benchmark: a miro-gen client's round trip over IIOP to a C++ omniORB server, against the same
call made by a C++ omniORB client, in the same run.

    python bench/bench_iiop.py [--calls N] [--rounds R] [--check]

The server is the C++ peer of the tests (tests/corba/peer.cc, built with omniidl and g++ as the
tests build it), serving Peer::Echo on loopback. Two calls: `nothing()` (no arguments, no
results: the cost of a request and a reply) and `echo_text("hello")` (a string each way). The
Python client is a generated stub over `IIOPInvoker`; the C++ client is omniORB's own stub, in a
process of its own. The two alternate in rounds of N calls each, so that the machine's changing
load falls on both alike; each row's p50 is the median of its rounds' p50s. Prints the p50s and
the ratios. Target (issue "Talk to the CORBA world"): within 2x; `--check` exits 1 when
`nothing()` misses it. Needs omniidl, g++ and libomniorb4-dev (as the tests do).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]

from corba_peers import CppPeer, build_peer, generate_python, missing_tools  # noqa: E402

from miro_gen.corba.client import IIOPInvoker  # noqa: E402

TARGET = 2.0


def python_round(echo: object, calls: int) -> tuple[float, float]:
    """p50 of `nothing()` and of `echo_text("hello")`, in microseconds."""
    nothing = echo.nothing  # type: ignore[attr-defined]
    text = echo.echo_text  # type: ignore[attr-defined]
    a, b = [], []
    clock = time.perf_counter
    for _ in range(calls):
        t0 = clock()
        nothing()
        t1 = clock()
        text("hello")
        t2 = clock()
        a.append(t1 - t0)
        b.append(t2 - t1)
    return statistics.median(a) * 1e6, statistics.median(b) * 1e6


def cpp_round(peer: Path, ior: str, calls: int) -> tuple[float, float]:
    out = subprocess.run(
        [str(peer), "bench", ior, str(calls)], capture_output=True, text=True, timeout=300
    ).stdout
    line = next(x for x in out.splitlines() if x.startswith("P50 "))
    _, nothing, text = line.split()
    return float(nothing), float(text)


def main() -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--calls", type=int, default=2000, help="calls per round (default 2000)")
    p.add_argument("--rounds", type=int, default=5, help="rounds of each (default 5)")
    p.add_argument("--check", action="store_true", help=f"exit 1 above {TARGET}x")
    ns = p.parse_args()
    missing = missing_tools()
    if missing:
        print(f"bench_iiop: needs {', '.join(missing)}", file=sys.stderr)
        return 2
    peer = build_peer()
    gen = Path(tempfile.mkdtemp(prefix="bench-iiop-"))
    generate_python(gen)
    sys.path.insert(0, str(gen))
    import Peer

    server = CppPeer(peer, "server", "-")
    invoker = IIOPInvoker()
    try:
        ior = server.ready()
        echo = invoker.stub(Peer.Echo, ior)
        python_round(echo, 500)  # connections, templates, caches
        cpp_round(peer, ior, 500)
        ours, theirs = [], []
        for _ in range(ns.rounds):
            ours.append(python_round(echo, ns.calls))
            theirs.append(cpp_round(peer, ior, ns.calls))
    finally:
        invoker.close()
        server.kill()
    rows = []
    for i, call in enumerate(("nothing()", 'echo_text("hello")')):
        mine = statistics.median(r[i] for r in ours)
        cpp = statistics.median(r[i] for r in theirs)
        rows.append((call, mine, cpp, mine / cpp))
    print(
        f"IIOP round trip to a C++ omniORB server, loopback, p50 of {ns.rounds} x {ns.calls} calls"
    )
    print(f"{'call':22} {'miro-gen (us)':>14} {'omniORB C++ (us)':>17} {'ratio':>7}")
    for call, mine, cpp, ratio in rows:
        print(f"{call:22} {mine:14.1f} {cpp:17.1f} {ratio:6.2f}x")
    worst = rows[0][3]
    print(f"target: within {TARGET}x ({'met' if worst <= TARGET else 'missed'} for nothing())")
    return 1 if ns.check and worst > TARGET else 0


if __name__ == "__main__":
    sys.exit(main())
