"""Benchmark: memory and service under the floods of issue 21, this checkout against a baseline.

    python bench/bench_floods.py [--baseline DIR] [--only NAME ...]

Each flood runs against fresh processes (`miro naming`, a server, a channel host) started from
a source tree: this checkout, and, with `--baseline`, another one (a checkout of the code
before issue 21, e.g. `git worktree add /tmp/before <commit>`), in the same run. For each it
prints the peak resident memory (VmHWM) of the attacked process and what the flood did to the
service, side by side:

* `unknown-ops`: 16,000 oneway requests with 65 KB made-up operation names to the naming
  service;
* `oversize`: four connections streaming 50 MB frames for 6 s at the naming service and at a
  server whose name must stay bound (lease 3 s): peak memory, and how often its name was
  missing when looked up every 0.1 s;
* `names`: one client binding 50,000 names: how many were accepted, peak memory;
* `names-owners`: the same client making up a new owner for each name (before issue 33: the
  table's limit, leases of 60 s ending meanwhile; since: the quota of its user, whatever owners
  it makes up);
* `connections`: 1,500 connections held open to the naming service (its cap is 1,024);
* `slow-subscriber`: a subscriber that never reads, on a channel hosted by the naming service,
  while a supplier pushes 1,000 events of 1 MiB;
* `comeback`: a channel's host killed and restarted: seconds from the new host's name being
  bound to the first event a consumer receives (the target is 2 s).

The machine these numbers come from is shared: run it a few times.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zmq
from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]


def hwm_mb(pid: int) -> float:
    """Peak resident memory of `pid` so far, MiB."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


class Tree:
    """A source tree whose processes the floods attack."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.env = dict(
            os.environ,
            PYTHONPATH=os.pathsep.join([str(root / "generated"), str(root)]),
            XDG_STATE_HOME=tempfile.mkdtemp(prefix="bench-floods-"),  # naming services' logs
        )

    def popen(self, *argv: str, stdout: int | None = subprocess.PIPE) -> subprocess.Popen[str]:
        return subprocess.Popen(
            [sys.executable, *argv],
            stdout=stdout,
            stderr=subprocess.DEVNULL,
            text=True,
            env=self.env,
            cwd=str(self.root),
        )

    def naming(self, *options: str) -> tuple[subprocess.Popen[str], str]:
        endpoint = f"tcp://127.0.0.1:{free_port()}"
        p = self.popen("-m", "miro_gen.cli.main", "naming", "--endpoint", endpoint, *options)
        assert p.stdout is not None
        p.stdout.readline()
        return p, endpoint

    def script(self, code: str, *args: str) -> subprocess.Popen[str]:
        return self.popen("-c", textwrap.dedent(code), *args)


def stop(*procs: subprocess.Popen[str]) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGKILL)
        p.wait(10)


def request(op: bytes, oneway: bool) -> list[bytes]:
    """A request frame in protocol version 1 for the naming service's object (a header of
    version, kind, flags, reserved, timeout, request id, key, operation; an empty CDR body)."""
    import struct

    key = b"NameService"
    head = struct.pack("<BBBBIQH", 1, 2 if oneway else 1, 0, 0, 0, 1, len(key)) + key
    return [head + struct.pack("<H", len(op)) + op, b"\x00\x01\x00\x00"]


# ---- the floods -------------------------------------------------------------------------------


def unknown_ops(tree: Tree) -> str:
    naming, endpoint = tree.naming()
    s = zmq.Context.instance().socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(endpoint)
    for n in range(16_000):
        s.send_multipart(request(f"{n:08d}".encode() + b"x" * 65_000, oneway=True))
    s.send_multipart(request(b"nothing", oneway=False))
    answered = bool(s.poll(120_000))
    peak = hwm_mb(naming.pid)
    s.close()
    stop(naming)
    return f"naming peak {peak:7.0f} MiB{'' if answered else '  (no answer after the flood)'}"


LOOKUP = """
import sys, time
import MiroNaming
from miro_gen import Client
c = Client(["x", "--naming", sys.argv[1]])
missing = checks = 0
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end:
    try:
        c.naming.registry.resolve("r/A")
    except Exception:
        missing += 1
    checks += 1
    time.sleep(0.1)
print(missing, checks, flush=True)
"""

VICTIM = """
import sys
import Miro__POA
from miro_gen import Server
class A(Miro__POA.Example):
    def getData(self): ...
    def setData(self, a, b): ...
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "r"])
server.add_to_name_service(A(), "A")
print(server.adapter.endpoint, flush=True)
server.run()
"""


def _stream(endpoint: str, size: int, stop_: threading.Event) -> None:
    ctx = zmq.Context()
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.SNDHWM, 4)
    s.connect(endpoint)
    head = request(b"x", oneway=True)[0]
    payload = bytes(size)
    while not stop_.is_set():
        try:
            s.send_multipart([head, payload], zmq.NOBLOCK)
        except zmq.Again:
            time.sleep(0.005)
    s.close()
    ctx.term()


def oversize(tree: Tree) -> str:
    naming, endpoint = tree.naming()
    victim = tree.script(VICTIM, endpoint)
    assert victim.stdout is not None
    target = victim.stdout.readline().strip()
    seconds = 6.0
    lookup = tree.script(LOOKUP, endpoint, str(seconds))
    stop_ = threading.Event()
    floods = [
        threading.Thread(target=_stream, args=(where, 50 << 20, stop_), daemon=True)
        for where in (endpoint, endpoint, endpoint, target)
    ]
    for f in floods:
        f.start()
    assert lookup.stdout is not None
    missing, checks = lookup.stdout.readline().split()
    stop_.set()
    for f in floods:
        f.join(10)
    result = (
        f"naming peak {hwm_mb(naming.pid):7.0f} MiB, server peak {hwm_mb(victim.pid):7.0f} MiB, "
        f"name missing in {missing} of {checks} look-ups"
    )
    stop(lookup, victim, naming)
    return result


BINDER = """
import sys
import MiroNaming
from miro_gen import Client
c = Client(["x", "--naming", sys.argv[1]])
accepted = 0
owners = sys.argv[3] == "many"
version2 = hasattr(MiroNaming.Registry, "bind_as")  # owners checked by the naming service
if version2:
    registry = c.naming.registry_stub(c.invoker, 5.0, owner=True)
for n in range(int(sys.argv[2])):
    entry = MiroNaming.Entry(f"flood/{n}", "IDL:x:1.0", "tcp://10.0.0.1:1", b"k", "")
    owner = f"owner{n}" if owners else "one-client"
    try:
        if version2:
            registry.bind_as(entry, MiroNaming.Owner(owner, owner), 60_000, False)
        else:
            c.naming.registry.rebind(entry, owner, 60_000)
        accepted += 1
    except Exception:
        pass
print(accepted, flush=True)
"""


def names(tree: Tree, owners: str = "one") -> str:
    naming, endpoint = tree.naming()
    binder = tree.script(BINDER, endpoint, "50000", owners)
    assert binder.stdout is not None
    accepted = binder.stdout.readline().strip()
    result = f"accepted {accepted:>6} of 50000 names, naming peak {hwm_mb(naming.pid):7.0f} MiB"
    stop(binder, naming)
    return result


BULK = """
import sys, time
import Miro
from miro_gen import Server, StructuredPushSupplier
import threading
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "bulk"])
supplier = StructuredPushSupplier(server.resolve_channel("Bulk"))
threading.Thread(target=server.run, daemon=True).start()
while not supplier.has_subscribers("Group"):
    time.sleep(0.01)
group = Miro.ExampleGroupIDL(0, [Miro.ExampleStructIDL(float(i), 0.0) for i in range(1 << 16)])
pushed = 0
for _ in range(1000):
    pushed += bool(supplier.push("Group", group))
    time.sleep(0.002)
time.sleep(1)
print(pushed, supplier.sent, supplier.dropped, flush=True)
"""


def slow_subscriber(tree: Tree) -> str:
    naming, endpoint = tree.naming("--channel", "Bulk")
    resolve = tree.script(
        """
        import sys
        from miro_gen import Client
        e = Client(["x", "--naming", sys.argv[1]]).naming.resolve("Bulk")
        print(bytes(e.key).decode(), flush=True)
        """,
        endpoint,
    )
    assert resolve.stdout is not None
    consumer_endpoint = resolve.stdout.readline().strip()
    stuck = zmq.Context.instance().socket(zmq.SUB)
    stuck.setsockopt(zmq.LINGER, 0)
    stuck.setsockopt(zmq.RCVHWM, 1)
    stuck.setsockopt(zmq.RCVBUF, 4096)
    stuck.setsockopt(zmq.SUBSCRIBE, b"")
    stuck.connect(consumer_endpoint)
    supplier = tree.script(BULK, endpoint)
    assert supplier.stdout is not None
    pushed, sent, dropped = supplier.stdout.readline().split()
    result = (
        f"channel host (naming) peak {hwm_mb(naming.pid):7.0f} MiB; supplier pushed {pushed}, "
        f"sent {sent}, dropped {dropped}"
    )
    stuck.close()
    stop(supplier, resolve, naming)
    return result


def connections(tree: Tree) -> str:
    naming, endpoint = tree.naming()
    contexts = [zmq.Context() for _ in range(3)]  # a context holds 1,023 sockets at most
    held = []
    for n in range(1500):
        s = contexts[n % 3].socket(zmq.DEALER)
        s.setsockopt(zmq.LINGER, 0)
        s.connect(endpoint)
        s.send_multipart(request(b"x", oneway=True))
        held.append(s)
    time.sleep(5)
    result = f"naming peak {hwm_mb(naming.pid):7.0f} MiB with 1,500 connections attempted"
    for ctx in contexts:
        ctx.destroy(0)
    stop(naming)
    return result


HOST = """
import sys, time
from miro_gen import EventChannelFactory, Server
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "robot"])
EventChannelFactory(server).create_channel("Events")
print(time.time(), flush=True)
server.run()
"""

PAIR = """
import sys, time, threading
import Miro
from miro_gen import Server, StructuredPushConsumer, StructuredPushSupplier
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "pair"])
channel = server.resolve_channel("robot/Events")
supplier = StructuredPushSupplier(channel)
got = []
class C(StructuredPushConsumer):
    def push_structured_event(self, event):
        got.append(time.time())
c = C(channel)
c.set_subscriptions([("*", "ExampleEvent")])
threading.Thread(target=server.run, daemon=True).start()
e = Miro.ExampleEventIDL(0, Miro.ExampleStructIDL(0.0, 0.0))
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end:
    supplier.push("ExampleEvent", e)
    time.sleep(0.01)
print(len(got), got[-1] if got else 0, flush=True)
for t in got:
    print(t, flush=True)
"""


def comeback(tree: Tree) -> str:
    naming, endpoint = tree.naming()
    host = tree.script(HOST, endpoint)
    assert host.stdout is not None
    host.stdout.readline()
    pair = tree.script(PAIR, endpoint, "20")
    time.sleep(3)
    stop(host)
    time.sleep(1)
    host = tree.script(HOST, endpoint)
    assert host.stdout is not None
    bound = float(host.stdout.readline())  # when create_channel returned: the name is bound
    assert pair.stdout is not None
    count, _ = pair.stdout.readline().split()
    times = [float(line) for line in pair.stdout.read().split()]
    after = [t for t in times if t > bound]
    stop(pair, host, naming)
    if not after:
        return f"consumer received {count} events, none after the restart (20 s)"
    return f"first event {after[0] - bound:5.2f} s after the new host was bound"


FLOODS: dict[str, Callable[[Tree], str]] = {
    "unknown-ops": unknown_ops,
    "oversize": oversize,
    "names": names,
    "names-owners": lambda tree: names(tree, "many"),
    "connections": connections,
    "slow-subscriber": slow_subscriber,
    "comeback": comeback,
}


def main() -> None:
    import resource

    _, most = resource.getrlimit(resource.RLIMIT_NOFILE)  # for the connections flood
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(most, 16384), most))
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--baseline", type=Path, help="another source tree to run the same floods on")
    p.add_argument("--only", nargs="*", choices=sorted(FLOODS), help="these floods only")
    ns = p.parse_args()
    trees = [("this checkout", Tree(ROOT))]
    if ns.baseline is not None:
        trees.append(("baseline", Tree(ns.baseline.resolve())))
    with tempfile.TemporaryDirectory():
        for name in ns.only or FLOODS:
            for label, tree in trees:
                started = time.monotonic()
                result = FLOODS[name](tree)
                took = time.monotonic() - started
                print(f"{name:16} {label:14} {result}  ({took:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
