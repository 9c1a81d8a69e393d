"""Benchmark: what the Zenoh router's access control per robot costs (`miro naming --zenoh
--per-robot`, transport/zenoh/access.py), both routers over mutual TLS, in one run on loopback.

    python bench/bench_zenoh_acl.py [--calls N] [--events N] [--runs R]

Two `miro naming --zenoh` routers with a fleet key made for the run: one with only TLS, one with
access control listing the robots. Every process holds a robot's own certificate (`miro keys
new ROBOT --ca fleet`) named after its naming context, so that under access control each is
checked against its own keys: the server (`r`), the caller (`b`), the supplier (`s`, its
events under its own domain) and the consumer (`c`). Calls: a generated stub's getData() to a
server in another process, p50 of the round trip. Events: ExampleEvents pushed by a supplier
and counted by a consumer of another session, both in this process: events/s. Interleaved
blocks, repeated R times (5); medians with their spread (min-max), the ratios acl/tls per run,
and the load average. Shared memory is Zenoh's default (its row says which).
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


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--calls", type=int, default=2000, help="calls per row, block and run")
    ap.add_argument("--events", type=int, default=20000, help="events per row and run")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    folder = tempfile.mkdtemp(prefix="miro-bench-keys-")
    key = os.path.join(folder, "fleet")
    kinds = ("tls", "acl")
    robots = [f"{role}{kind}" for kind in kinds for role in "rbsc"]
    for name, ca in [("fleet", []), *((r, ["--ca", key]) for r in robots)]:
        made = subprocess.run(
            [sys.executable, "-m", "miro_gen.cli.main", "keys", "new", os.path.join(folder, name),
             *ca],
            capture_output=True, text=True, env=service_env(),
        )  # fmt: skip
        assert made.returncode == 0, made.stderr
    shm = "on" if shared_memory(config("client")) else "off"
    procs: list[subprocess.Popen[str]] = []
    options: dict[str, list[str]] = {}
    try:
        for kind in kinds:
            endpoint = f"tcp://127.0.0.1:{free_port()}"
            acl = ["--per-robot", ",".join(r for r in robots if r.endswith(kind))]
            procs.append(start([sys.executable, "-m", "miro_gen.cli.main", "naming", "--zenoh",
                                "--endpoint", endpoint, "--log-file", "none", "--keys", key,
                                *(acl if kind == "acl" else [])]))  # fmt: skip
            options[kind] = ["--transport", "zenoh", "--naming", endpoint]
            procs.append(start([sys.executable, NAMED, *options[kind], "-MNC", f"r{kind}",
                                "--keys", os.path.join(folder, f"r{kind}")]))  # fmt: skip
        stubs, clients, events = {}, [], {}
        for kind, opts in options.items():

            def keyed(role: str, kind: str = kind) -> list[str]:
                return ["--keys", os.path.join(folder, f"{role}{kind}"), "-MNC", f"{role}{kind}"]

            client = Client(["b", *opts, *keyed("b")])
            clients.append(client)
            stubs[kind] = client.resolve_name(f"r{kind}/ExampleA", Miro.Example, wait=10)
            sup_server = Server(["s", *opts, *keyed("s")])
            con_server = Server(["c", *opts, *keyed("c")])
            for s in (sup_server, con_server):
                threading.Thread(target=s.run, daemon=True).start()
            channel = EventChannelFactory(sup_server).create_channel("Bench")
            consumer = Counter(con_server.resolve_channel(f"s{kind}/Bench"))
            consumer.set_subscriptions([("*", "ExampleEvent")])
            events[kind] = (sup_server, con_server, StructuredPushSupplier(channel), consumer)
        time.sleep(1.0)
        for _ in range(300):  # warm up
            stubs["tls"].getData(), stubs["acl"].getData()
        names = {
            "tls": "miro-gen over Zenoh, mutual TLS",
            "acl": "mutual TLS, access control per robot",
        }
        compare_pair(kinds, names, stubs, events, args, shm, "acl/tls")
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
