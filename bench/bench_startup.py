"""Benchmark: from process start to "resolvable in the naming service", and the idle memory
of a service, against Pyro5's equivalent (a daemon registering one object in its name server).

    python bench/bench_startup.py [--runs N] [--imports N] [--tree CHECKOUT]

Each run starts a fresh process and polls the naming service from this one until the name
resolves; the time is from the start of the process to the first successful lookup. Rows:
ExampleA (`python services/exampleA.py`), the same through `miro run exampleA` (in the same
interpreter), a `miro new` server (`miro run`; it reads its run-time parameters, which loads the
parameter runtime), the same server without `miro run` (`python -m services.bench_server`: what
the launcher adds), and the Pyro5 server (`pip install miro-gen[bench]`). The idle resident
memory (VmRSS) of each is read a second after it became resolvable, its CPU time (user + system,
steadier than the wall clock on a shared machine) when it became resolvable. Prints the medians
and the ratio of each to Pyro5. `--tree` runs the services (and the naming service) from another
checkout, e.g. the tree before a change from `git archive`. Targets (issue 30): ExampleA and the
`miro new` server resolvable in at most 1.5x Pyro5's time, the `miro new` server's idle memory
at most 1.5x Pyro5's. The machine's load changes the absolute times: runs are interleaved, so
that it falls on every row alike.

`--imports N` then starts the `miro new` server once more under `python -X importtime` and
prints what it imported until its name resolved: the number of modules, and the N imports
that took longest, with and without what they imported in turn.
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
import time
from collections.abc import Callable
from pathlib import Path

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import MiroNaming  # noqa: E402
import zmq  # noqa: E402

from miro_gen.transport.naming.client import NamingClient  # noqa: E402
from miro_gen.transport.rpc.invoker import ZmqInvoker  # noqa: E402

TARGET = 1.5  # time to resolvable, and idle memory, against Pyro5's
PYRO = "Pyro5 daemon + name server"
EXAMPLE_A = "python services/exampleA.py"
MIRO_NEW = "miro run (a miro new server)"
NEW_DIRECT = "python -m services.bench_server"

try:
    import Pyro5.api as pyro
    import Pyro5.errors as pyro_errors
except ImportError:  # optional: pip install miro-gen[bench]
    pyro = None

PYRO_SERVER = """
import sys
import Pyro5.api

@Pyro5.api.expose
class Example:
    def getData(self):
        return (1.0, 2.0)

daemon = Pyro5.api.Daemon(host="127.0.0.1")
ns = Pyro5.api.locate_ns(host="127.0.0.1", port=int(sys.argv[1]))
ns.register("bench.Example", daemon.register(Example))
daemon.requestLoop()
"""


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def cpu_s(pid: int) -> float:
    """The CPU time (user + system) `pid` has used so far: steadier than the wall clock on a
    shared machine, where a process waits for a core."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


TREE = ROOT  # the checkout whose code the services run (--tree)


def env() -> dict[str, str]:
    """The services' environment: the tree's code on the path, and bytecode cached as an
    installed package has it (a PYTHONDONTWRITEBYTECODE inherited from the shell would have
    every start compile miro-gen's and the generated modules from source, and not Pyro5's,
    which pip compiled when it installed it)."""
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(TREE / "generated"), str(TREE)])
    e.pop("PYTHONDONTWRITEBYTECODE", None)
    return e


def timed_start(
    args: list[str],
    resolvable: Callable[[], bool],
    cwd: Path | None = None,
    stderr: int | None = None,
) -> tuple[float, float, float]:
    """Start `args`; seconds until `resolvable()`, the idle RSS (MB) a second later, and the
    CPU seconds it had used when it became resolvable."""
    start = time.perf_counter()
    proc = subprocess.Popen(args, cwd=cwd, env=env(), stdout=subprocess.DEVNULL, stderr=stderr)
    try:
        while not resolvable():
            if proc.poll() is not None:
                raise RuntimeError(f"{args} ended with status {proc.returncode}")
            time.sleep(0.001)
        took = time.perf_counter() - start
        cpu = cpu_s(proc.pid)
        time.sleep(1.0)
        return took, rss_mb(proc.pid), cpu
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class Naming:
    """`miro naming` in a process, and a client that asks it for a name."""

    def __init__(self) -> None:
        self.endpoint = f"tcp://127.0.0.1:{free_port()}"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "miro_gen.cli.main", "naming", "--endpoint", self.endpoint],
            stdout=subprocess.PIPE,
            text=True,
            env=env(),
        )
        assert self.proc.stdout is not None
        self.proc.stdout.readline()
        self.invoker = ZmqInvoker(zmq.Context())
        self.client = NamingClient(self.invoker, self.endpoint, "bench")

    def resolver(self, name: str) -> Callable[[], bool]:
        def resolvable() -> bool:
            try:
                self.client.registry.resolve(name)
            except MiroNaming.NotFound:
                return False
            return True

        return resolvable

    def close(self) -> None:
        self.invoker.close()
        self.proc.kill()
        self.proc.wait()


class PyroNaming:
    """Pyro5's name server in a process, and a proxy that asks it for a name."""

    def __init__(self) -> None:
        self.port = free_port()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "Pyro5.nameserver", "-n", "127.0.0.1", "-p", str(self.port)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for _ in range(1000):
            try:
                pyro.locate_ns(host="127.0.0.1", port=self.port)._pyroRelease()
                break
            except pyro_errors.NamingError:
                time.sleep(0.01)

    def resolvable(self) -> bool:
        with pyro.locate_ns(host="127.0.0.1", port=self.port) as ns:
            try:
                ns.lookup("bench.Example")
            except pyro_errors.NamingError:
                return False
            with ns:
                ns.remove("bench.Example")  # for the next run
            return True

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


def scaffold(folder: Path) -> Path:
    """A project with a `miro new` server (Miro::Example, bound as BenchServer)."""
    made = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "new", "bench_server", "--pattern", "server"],
        cwd=folder,
        env=env(),
        capture_output=True,
        text=True,
    )
    if made.returncode != 0:
        raise RuntimeError(made.stderr)
    return folder


def import_report(lines: list[str], top: int) -> None:
    """The modules of a `-X importtime` trace, and the imports that took longest."""
    rows = []
    for line in lines:
        if not line.startswith("import time:") or "|" not in line or "self [us]" in line:
            continue
        own, total, name = line[len("import time:") :].split("|")
        rows.append((int(own), int(total), name.strip()))
    print(f"\n{len(rows)} modules imported until resolvable; CPU time is shared, so the")
    print("microseconds below carry the machine's load (compare their order, not their size)")
    head = f"{'longest with what they import':46} {'us':>9}    {'longest on their own':36}"
    print(f"{head} {'us':>8}")
    by_total = sorted(rows, key=lambda r: -r[1])[:top]
    by_own = sorted(rows, key=lambda r: -r[0])[:top]
    for (_, total, a), (own, _, b) in zip(by_total, by_own, strict=True):
        print(f"{a:46} {total:9d}    {b:36} {own:8d}")


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--runs", type=int, default=10, help="starts per row (default 10)")
    ap.add_argument("--imports", type=int, default=0, help="report the N longest imports")
    ap.add_argument(
        "--tree",
        type=Path,
        default=ROOT,
        help="the miro-gen checkout the services run from (on PYTHONPATH; default: this one), "
        "e.g. the tree before a change, from `git archive`",
    )
    args = ap.parse_args()
    global TREE
    TREE = args.tree.resolve()
    print(f"services from {TREE}")
    naming = Naming()
    pyro_naming = PyroNaming() if pyro is not None else None
    project = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    common = ["--naming", naming.endpoint, "-MNC", "bench"]
    new_server = [sys.executable, "-m", "miro_gen.cli.main", "run", "bench_server", *common]
    rows: dict[str, Callable[[], tuple[float, float, float]]] = {
        EXAMPLE_A: lambda: timed_start(
            [sys.executable, str(TREE / "services" / "exampleA.py"), *common],
            naming.resolver("bench/ExampleA"),
        ),
        "miro run exampleA": lambda: timed_start(
            [sys.executable, "-m", "miro_gen.cli.main", "run", "exampleA", *common],
            naming.resolver("bench/ExampleA"),
            cwd=project,
        ),
        MIRO_NEW: lambda: timed_start(
            new_server, naming.resolver("bench/BenchServer"), cwd=project
        ),
        NEW_DIRECT: lambda: timed_start(
            [sys.executable, "-m", "services.bench_server", *common],
            naming.resolver("bench/BenchServer"),
            cwd=project,
        ),
    }
    if pyro_naming is not None:
        rows[PYRO] = lambda: timed_start(
            [sys.executable, "-c", PYRO_SERVER, str(pyro_naming.port)], pyro_naming.resolvable
        )
    samples: dict[str, list[tuple[float, float, float]]] = {name: [] for name in rows}
    print(f"load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    try:
        scaffold(project)
        for run in rows.values():  # once unmeasured: bytecode cached, a project's stamp made
            run()
        for _ in range(args.runs):
            for name, run in rows.items():
                samples[name].append(run())
        if args.imports:
            trace = project / "importtime.txt"
            with trace.open("w") as err:
                timed_start(
                    [new_server[0], "-X", "importtime", *new_server[1:]],
                    naming.resolver("bench/BenchServer"),
                    cwd=project,
                    stderr=err.fileno(),
                )
            import_report(trace.read_text().splitlines(), args.imports)
    finally:
        naming.close()
        if pyro_naming is not None:
            pyro_naming.close()
        shutil.rmtree(project, ignore_errors=True)
    medians = {
        name: tuple(statistics.median(x[i] for x in s) for i in range(3))
        for name, s in samples.items()
    }
    base, base_rss, base_cpu = medians.get(PYRO, (float("nan"),) * 3)
    print()
    print(f"{'start to resolvable (median of ' + str(args.runs) + ')':40} {'ms':>7} "
          f"{'ratio':>6} {'idle RSS MB':>12} {'ratio':>6} {'CPU ms':>7} {'ratio':>6}")  # fmt: skip
    for name, (took, rss, cpu) in medians.items():
        print(
            f"{name:40} {took * 1000:7.1f} {took / base:6.2f} {rss:12.1f} {rss / base_rss:6.2f}"
            f" {cpu * 1000:7.0f} {cpu / base_cpu:6.2f}"
        )
    print(f"load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if pyro_naming is None:
        print("Pyro5: skipped (pip install miro-gen[bench])")
        return 0
    checks = [
        ("ExampleA time / Pyro5", medians[EXAMPLE_A][0] / base),
        ("miro run exampleA time / Pyro5", medians["miro run exampleA"][0] / base),
        ("miro new server time / Pyro5", medians[MIRO_NEW][0] / base),
        ("miro new server idle RSS / Pyro5", medians[MIRO_NEW][1] / base_rss),
    ]
    for what, ratio in checks:
        verdict = "ok" if ratio <= TARGET else "MISSED"
        print(f"{what}: {ratio:.2f} (target <= {TARGET}: {verdict})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
