"""Benchmark: what the Zenoh backbone's security costs, two set-ups in one run on loopback.

    python bench/bench_zenoh_security.py --pair tls|acl [--calls N] [--events N] [--runs R]

`--pair tls`: mutual TLS against plain TCP. `--pair acl`: access control per robot
(`miro naming --zenoh --per-robot`, transport/zenoh/access.py) against mutual TLS alone.

Each set-up has its own `miro naming --zenoh` router. With TLS, a fleet key is made for the run
(`miro keys new`: TLS even on loopback, as a key given is always used), and every process holds
a robot's own certificate (`miro keys new ROBOT --ca fleet`) named after its naming context, so
that under access control each is checked against its own keys: the server (`r`), the caller
(`b`), the supplier (`s`, its events under its own domain) and the consumer (`c`). Calls: a
generated stub's getData() to a server in another process, p50 of the round trip. Events:
ExampleEvents pushed by a supplier and counted by a consumer of another session, both in this
process: events/s. Interleaved blocks, repeated R times (5); medians with their spread
(min-max), the ratio of the two set-ups per run, and the load average. Shared memory is
Zenoh's default (its row says which); the messages here are under its 3 KiB threshold.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests"), str(ROOT / "bench")]
os.environ.setdefault("MIRO_DISCOVERY", "0")

import Miro  # noqa: E402
from bench_backbones import Counter, compare_pair, start  # noqa: E402
from loopback import free_port, service_env  # noqa: E402

from miro_gen import Client, EventChannelFactory, Server, StructuredPushSupplier  # noqa: E402
from miro_gen.transport.zenoh.session import config, shared_memory  # noqa: E402

NAMED = str(ROOT / "tests" / "procs" / "named_example.py")
MIRO = [sys.executable, "-m", "miro_gen.cli.main"]
PAIRS = {"tls": ("plain", "tls"), "acl": ("tls", "acl")}  # --pair: (the baseline, measured)
NAMES = {
    "plain": "miro-gen over Zenoh, plain TCP",
    "tls": "miro-gen over Zenoh, mutual TLS",
    "acl": "mutual TLS, access control per robot",
}
LABELS = {"tls": "TLS/plain", "acl": "acl/tls"}
ROLES = "rbsc"  # server, caller, supplier, consumer


def make_keys(folder: str, kinds: tuple[str, str]) -> None:
    """The fleet's key and, for each set-up with TLS, a certificate per role signed by it."""
    fleet = os.path.join(folder, "fleet")
    robots = [f"{role}{kind}" for kind in kinds if kind != "plain" for role in ROLES]
    for name, ca in [("fleet", []), *((r, ["--ca", fleet]) for r in robots)]:
        made = subprocess.run([*MIRO, "keys", "new", os.path.join(folder, name), *ca],
                              capture_output=True, text=True, env=service_env())  # fmt: skip
        assert made.returncode == 0, made.stderr


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--pair", choices=sorted(PAIRS), required=True, help="what to compare")
    ap.add_argument("--calls", type=int, default=2000, help="calls per row, block and run")
    ap.add_argument("--events", type=int, default=20000, help="events per row and run")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    kinds = PAIRS[args.pair]
    folder = tempfile.mkdtemp(prefix="miro-bench-keys-")
    make_keys(folder, kinds)
    shm = "on" if shared_memory(config("client")) else "off"
    procs: list[subprocess.Popen[str]] = []
    options: dict[str, list[str]] = {}
    try:
        for kind in kinds:
            endpoint = f"tcp://127.0.0.1:{free_port()}"
            router = ["--keys", os.path.join(folder, "fleet")] if kind != "plain" else []
            if kind == "acl":
                router += ["--per-robot", ",".join(f"{role}{kind}" for role in ROLES)]
            procs.append(start([*MIRO, "naming", "--zenoh", "--endpoint", endpoint,
                                "--log-file", "none", *router]))  # fmt: skip
            options[kind] = ["--transport", "zenoh", "--naming", endpoint]
        stubs, clients, events = {}, [], {}
        for kind, opts in options.items():

            def own(role: str, kind: str = kind, opts: list[str] = opts) -> list[str]:
                keys = ["--keys", os.path.join(folder, f"{role}{kind}")] if kind != "plain" else []
                return [*opts, *keys, "-MNC", f"{role}{kind}"]

            procs.append(start([sys.executable, NAMED, *own("r")]))
            client = Client(["b", *own("b")])
            clients.append(client)
            stubs[kind] = client.resolve_name(f"r{kind}/ExampleA", Miro.Example, wait=10)
            sup_server = Server(["s", *own("s")])
            con_server = Server(["c", *own("c")])
            for s in (sup_server, con_server):
                threading.Thread(target=s.run, daemon=True).start()
            channel = EventChannelFactory(sup_server).create_channel("Bench")
            consumer = Counter(con_server.resolve_channel(f"s{kind}/Bench"))
            consumer.set_subscriptions([("*", "ExampleEvent")])
            events[kind] = (sup_server, con_server, StructuredPushSupplier(channel), consumer)
        time.sleep(1.0)
        for _ in range(300):  # warm up
            for kind in kinds:
                stubs[kind].getData()
        compare_pair(kinds, NAMES, stubs, events, args, shm, LABELS[args.pair])
        for sup_server, con_server, _, _ in events.values():
            sup_server.shutdown()
            con_server.shutdown()
        for client in clients:
            client.close()
    finally:
        for p in procs:
            p.kill()
            p.wait()
        subprocess.run(["rm", "-rf", folder], check=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
