"""Benchmark: what the Zenoh backbone's mutual TLS costs, plain TCP and TLS in one run on
loopback.

    python bench/bench_zenoh_tls.py [--calls N] [--events N] [--runs R]

Two `miro naming --zenoh` routers: one plain, one with a fleet key made for the run (`miro keys
new`: TLS even on loopback, as a key given is always used). Calls: a generated stub's
getData() to a server in another process, through each router, p50 of the round trip. Events:
ExampleEvents pushed by a supplier and counted by a consumer of another session, both in this
process, through each router: events/s. Interleaved blocks, repeated R times (5); medians with
their spread (min-max), the ratios TLS/plain per run, and the load average. Shared memory is
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
    made = subprocess.run([sys.executable, "-m", "miro_gen.cli.main", "keys", "new", key],
                          capture_output=True, text=True, env=service_env())  # fmt: skip
    assert made.returncode == 0, made.stderr
    shm = "on" if shared_memory(config("client")) else "off"
    procs: list[subprocess.Popen[str]] = []
    options: dict[str, list[str]] = {}
    try:
        for kind, keys in (("plain", []), ("tls", ["--keys", key])):
            endpoint = f"tcp://127.0.0.1:{free_port()}"
            procs.append(start([sys.executable, "-m", "miro_gen.cli.main", "naming", "--zenoh",
                                "--endpoint", endpoint, "--log-file", "none", *keys]))  # fmt: skip
            options[kind] = ["--transport", "zenoh", "--naming", endpoint, *keys]
            procs.append(start([sys.executable, NAMED, *options[kind], "-MNC", "r"]))
        stubs, clients, events = {}, [], {}
        for kind, opts in options.items():
            client = Client(["b", *opts])
            clients.append(client)
            stubs[kind] = client.resolve_name("r/ExampleA", Miro.Example, wait=10)
            sup_server = Server(["s", *opts, "-MNC", f"s{kind}"])
            con_server = Server(["c", *opts, "-MNC", f"c{kind}"])
            for s in (sup_server, con_server):
                threading.Thread(target=s.run, daemon=True).start()
            channel = EventChannelFactory(sup_server).create_channel("Bench")
            consumer = Counter(con_server.resolve_channel(f"s{kind}/Bench"))
            consumer.set_subscriptions([("*", "ExampleEvent")])
            events[kind] = (sup_server, con_server, StructuredPushSupplier(channel), consumer)
        time.sleep(1.0)
        for _ in range(300):  # warm up
            stubs["plain"].getData(), stubs["tls"].getData()
        names = {
            "plain": "miro-gen over Zenoh, plain TCP",
            "tls": "miro-gen over Zenoh, mutual TLS",
        }
        compare_pair(("plain", "tls"), names, stubs, events, args, shm, "TLS/plain")
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
