"""Benchmark: `miro foxglove` against a raw foxglove-sdk server publishing the same bytes.

    python bench/bench_foxglove.py [--seconds 3] [--repeats 5] [--check]

Two sizes: small events (Miro::ExampleEventIDL, 28 bytes of CDR) and 1 MB events
(Miro::ImageEventIDL). For each, two ways to a Foxglove client, interleaved, `--repeats` times:

* raw: a process runs the Foxglove SDK's server itself and logs the very same payload bytes
  flat out on a channel of the same schema, with the call the bridge makes
  (`BaseChannel.log`) and the bridge's client queue (what an SDK user writes at best: no
  middleware between);
* ours, right after: a supplier process offers the events at the rate the raw server
  delivered (frames built once and sent again without copying, paced, so that the supplier
  costs about what the raw loop's making of a message does: nothing) into an event channel
  that a naming service hosts; `miro foxglove` forwards them to the client. The ratio says how
  much of what the SDK alone carried the bridge carries (at most about 1: it is offered no
  more).

Like with like: the same payload bytes (the client hashes the first message of each run; a
difference stops the bench), the same wheel's WebSocket server with the same client queue,
over loopback TCP, to the same client: Foxglove's ws-protocol client over `ws` in node
(tests/foxglove: `npm ci`), which subscribes and counts the messages (and bytes) that reach it
from its first to the end of `--seconds` (at least 2 s of work per run). What differs is what
the bridge is: the event channel between the supplier and the SDK. Printed: messages/s and
MB/s of each, their medians with the spread (min-max), ours/raw of the medians and of each
run, and the load average. Target (issue 31): at least 0.8x raw for both sizes; `--check`
exits 1 when missed.

With `--fairness`: a supplier pushes a 6 MB camera (Miro::ImageEventIDL) at 30 Hz and a 100 Hz
small topic (Miro::ExampleEventIDL) through `miro foxglove` (its default --client-queue) to
the client of tests/foxglove/client.mjs, which counts what it received of each by the numbers
the supplier gave (`frame`, `counter`) during 300 of the small ones: the share of each that
arrived, per run. Target (issue 31): at least 95% of each.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

from raw_peers import free_port  # beside this file

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]
from miro_gen.foxglove import DEFAULT_BACKLOG  # noqa: E402  (the bridge's, given the raw server too)

NODE_DIR = ROOT / "tests" / "foxglove"
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "generated"), str(ROOT)]))
TARGET = 0.8
SIZES = {"small": 0, "1 MB": 1 << 20}

# The payload of a size: the same bytes for both ways.
PAYLOAD = """
import Miro
def payload(size):
    if size == 0:
        return Miro.ExampleEventIDL, Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, 2.0))
    form = Miro.ImageFormatIDL(1024, size // 1024, Miro.IMAGE_MONO8, 1024)
    return Miro.ImageEventIDL, Miro.ImageEventIDL(Miro.TimeIDL(1, 0), 1, form, bytes(size))
"""

# The stream offered to the bridge: a StructuredPushSupplier offers the type (the bridge
# advertises what services offer), then the events go as frames built once before the run (up
# to 100 small events a frame, as the transport batches them; a large one alone) and sent
# again and again without copying (ZeroMQ's zero-copy send for large frames), paced at RATE
# events/s (the rate the raw server delivered in the same repeat): the supplier costs about
# what the raw server's loop costs to make a message (nothing), so that the bridge's own cost
# is what is measured. The events' sequence numbers repeat (the bridge does not read them).
SUPPLIER = (
    PAYLOAD
    + """
import os, sys, threading, time, zmq
from miro_gen import Server, StructuredPushSupplier
from miro_gen.transport.events.frames import EVENT, batch_head, topic
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "bench"])
cls, value = payload(int(sys.argv[2]))
rate = float(sys.argv[3])
channel = server.resolve_channel("EventChannel")
supplier = StructuredPushSupplier(channel)
threading.Thread(target=server.run, daemon=True).start()
supplier.push("Bench", value)  # offered: the bridge advertises it
data = value.serialize()
most = 100 if len(data) < 65536 else 1
sock = zmq.Context().socket(zmq.PUB)
sock.setsockopt(zmq.SNDHWM, 1000)
sock.connect(channel.supplier_endpoint)
head = topic("bench", "Bench")
raw_hash = bytes.fromhex(cls._type_hash)
supplier_id = int.from_bytes(os.urandom(8), "little")
event = EVENT.pack(0, 0, 0, len(data)) + data
frames = {n: batch_head(n, supplier_id, raw_hash) + event * n for n in range(1, most + 1)}
print("READY", flush=True)
seq = 0
start = time.monotonic()
while True:
    due = int((time.monotonic() - start) * rate) + 1
    while seq < due:
        n = min(most, due - seq)
        seq += n
        try:
            sock.send_multipart([head, frames[n]], zmq.NOBLOCK, copy=False)
        except zmq.Again:
            pass
    time.sleep(0.001)
"""
)

RAW_SERVER = (
    PAYLOAD
    + """
import sys, time, foxglove
cls, value = payload(int(sys.argv[1]))
data = value.serialize()
ctx = foxglove.Context()
channel = foxglove.Channel(
    "bench/Bench",
    message_encoding="cdr",
    schema=foxglove.Schema(name=cls._type_name, encoding="omgidl", data=cls._data_schema.encode()),
    context=ctx,
)
server = foxglove.start_server(port=0, context=ctx, message_backlog_size=int(sys.argv[2]))
print(server.port, flush=True)
log = channel.base.log  # the SDK's own call, as the bridge makes it
while True:
    log(data)
"""
)

# Counts what reaches a Foxglove client (cwd: tests/foxglove, for its node_modules).
COUNTER = """
import { createHash } from "node:crypto";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";
const [url, seconds] = process.argv.slice(1);
const ws = new WebSocket(url, ["foxglove.sdk.v1"]);
ws.binaryType = "arraybuffer";
const client = new wsProtocol.FoxgloveClient({ ws });
let first = 0, count = 0, bytes = 0, digest = "";
client.on("advertise", (channels) => {
  const c = channels.find((c) => c.topic === "bench/Bench");
  if (c) client.subscribe(c.id);
});
client.on("message", (m) => {
  const now = performance.now();
  if (first === 0) {
    first = now;
    const d = m.data;
    const payload = new Uint8Array(d.buffer, d.byteOffset, d.byteLength);
    digest = createHash("sha256").update(payload).digest("hex");
    setTimeout(() => {
      const s = (performance.now() - first) / 1000;
      const result = { rate: count / s, mbps: bytes / s / 1e6, digest };
      process.stdout.write(JSON.stringify(result) + "\\n");
      process.exit(0);
    }, Number(seconds) * 1000);
  }
  count += 1;
  bytes += m.data.byteLength;
});
"""


def count(url: str, seconds: float, who: str) -> dict[str, Any]:
    try:
        done = subprocess.run(
            ["node", "--input-type=module", "-e", COUNTER, url, str(seconds)],
            capture_output=True,
            text=True,
            cwd=NODE_DIR,
            timeout=seconds + 60,
        )
    except subprocess.TimeoutExpired:
        raise SystemExit(f"bench_foxglove: no message from {who} in a minute") from None
    if done.returncode != 0:
        raise SystemExit(f"the client failed: {done.stderr}")
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def stop(*procs: subprocess.Popen[str]) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def run_raw(size: int, seconds: float, queue: int) -> dict[str, Any]:
    server = subprocess.Popen(
        [sys.executable, "-c", RAW_SERVER, str(size), str(queue)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,  # the SDK's lines about the client that went
        text=True,
        env=ENV,
    )
    try:
        assert server.stdout is not None
        port = int(server.stdout.readline())
        return count(f"ws://127.0.0.1:{port}", seconds, "the raw server")
    finally:
        stop(server)


def run_ours(size: int, seconds: float, rate: float, queue: int) -> dict[str, Any]:
    naming_endpoint = f"tcp://127.0.0.1:{free_port()}"
    miro = [sys.executable, "-m", "miro_gen.cli.main"]
    naming = subprocess.Popen(
        [*miro, "naming", "--endpoint", naming_endpoint, "--channel", "EventChannel"],
        stdout=subprocess.PIPE,
        text=True,
        env=ENV,
    )
    procs = [naming]
    try:
        assert naming.stdout is not None
        naming.stdout.readline()
        supplier = subprocess.Popen(
            [sys.executable, "-c", SUPPLIER, naming_endpoint, str(size), str(rate)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,  # KeyboardInterrupt at the end
            text=True,
            env=ENV,
        )
        procs.append(supplier)
        assert supplier.stdout is not None
        supplier.stdout.readline()
        bridge = subprocess.Popen(
            [
                *miro,
                "foxglove",
                "--naming",
                naming_endpoint,
                "-MNC",
                "bridge",
                "--port",
                "0",
                "--client-queue",
                str(queue),
            ],
            stderr=subprocess.PIPE,
            text=True,
            env=ENV,
        )
        procs.append(bridge)
        assert bridge.stderr is not None
        line = bridge.stderr.readline()
        port = line.split("ws://127.0.0.1:")[1].split()[0]
        return count(f"ws://127.0.0.1:{port}", seconds, "the bridge")
    finally:
        stop(*reversed(procs))


STREAMS = """
import sys
import Miro
from miro_gen import Server, StructuredPushSupplier
server = Server(sys.argv[:1] + ["--naming", sys.argv[1], "-MNC", "bench"])
supplier = StructuredPushSupplier(server.resolve_channel("EventChannel"))
form = Miro.ImageFormatIDL(1024, 6_000_000 // 3072, Miro.IMAGE_RGB8, 3072)
pixels = bytes(6_000_000)
n = {"camera": 0, "fast": 0}
def camera(_=None):
    supplier.push("Camera", Miro.ImageEventIDL(Miro.TimeIDL(0, 0), n["camera"], form, pixels))
    n["camera"] += 1
def fast(_=None):
    supplier.push("Fast", Miro.ExampleEventIDL(n["fast"], Miro.ExampleStructIDL()))
    n["fast"] += 1
server.reactor().schedule_timer(0.0, 1 / 30, camera)
server.reactor().schedule_timer(0.0, 1 / 100, fast)
server.reactor().call_soon(lambda: print("READY", flush=True))
server.run()
"""


def fairness(repeats: int) -> bool:
    """The camera beside the small topic; whether every share met 95%."""
    naming_endpoint = f"tcp://127.0.0.1:{free_port()}"
    miro = [sys.executable, "-m", "miro_gen.cli.main"]
    naming = subprocess.Popen(
        [*miro, "naming", "--endpoint", naming_endpoint, "--channel", "EventChannel"],
        stdout=subprocess.PIPE,
        text=True,
        env=ENV,
    )
    procs = [naming]
    met = True
    try:
        assert naming.stdout is not None
        naming.stdout.readline()
        streams = subprocess.Popen(
            [sys.executable, "-c", STREAMS, naming_endpoint],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=ENV,
        )
        procs.append(streams)
        assert streams.stdout is not None
        streams.stdout.readline()
        bridge = subprocess.Popen(
            [*miro, "foxglove", "--naming", naming_endpoint, "-MNC", "bridge", "--port", "0"],
            stderr=subprocess.PIPE,
            text=True,
            env=ENV,
        )
        procs.append(bridge)
        assert bridge.stderr is not None
        url = "ws://127.0.0.1:" + bridge.stderr.readline().split("ws://127.0.0.1:")[1].split()[0]
        # TimeIDL is two longs: the frame number is at 4 + 8 (after the encapsulation)
        step = {
            "op": "count",
            "topics": ["bench/Camera", "bench/Fast"],
            "keys": {"bench/Camera": 12, "bench/Fast": 4},
            "last": "bench/Fast",
            "until": 300,
        }
        print("| run | camera frames | camera share | small events | small share |")
        print("|---|---:|---:|---:|---:|")
        for run in range(repeats):
            done = subprocess.run(
                ["node", str(NODE_DIR / "client.mjs"), url, json.dumps([step])],
                capture_output=True,
                text=True,
                cwd=NODE_DIR,
                timeout=120,
            )
            counts = json.loads(done.stdout.splitlines()[1])["counts"]
            shares = []
            for topic in ("bench/Camera", "bench/Fast"):
                got = counts[topic]
                shares.append((len(got), len(got) / (got[-1] - got[0] + 1)))
            met &= all(share >= 0.95 for _, share in shares)
            (nc, sc), (nf, sf) = shares
            print(f"| {run + 1} | {nc} | {sc:.1%} | {nf} | {sf:.1%} |", flush=True)
    finally:
        stop(*reversed(procs))
    return met


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):,.0f} ({min(values):,.0f}-{max(values):,.0f})"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=3.0, help="counted per run (default 3)")
    p.add_argument("--repeats", type=int, default=5, help="interleaved runs of each (default 5)")
    p.add_argument("--check", action="store_true", help=f"exit 1 below {TARGET}x raw")
    p.add_argument(
        "--client-queue",
        type=int,
        default=DEFAULT_BACKLOG,
        help=f"messages kept per client by both servers (default: the bridge's, {DEFAULT_BACKLOG})",
    )
    p.add_argument(
        "--fairness", action="store_true", help="the 6 MB, 30 Hz camera beside a 100 Hz topic"
    )
    ns = p.parse_args()
    try:
        import foxglove  # noqa: F401
    except ImportError:
        print("bench_foxglove: skipped: foxglove-sdk is not installed (the foxglove extra)")
        return 0
    if not (NODE_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        print("bench_foxglove: skipped: run `npm ci` in tests/foxglove first")
        return 0
    load = os.getloadavg()[0]
    if ns.fairness:
        print(f"load average {load:.1f}; a 6 MB camera at 30 Hz beside a 100 Hz topic")
        met = fairness(ns.repeats)
        print(f"load average after: {os.getloadavg()[0]:.1f}; target 95% of each")
        return 1 if ns.check and not met else 0
    missed = False
    print(
        f"load average {load:.1f}; {ns.repeats} interleaved runs of {ns.seconds:g} s each;"
        f" client queue {ns.client_queue} messages"
    )
    print(
        "| events | ours msg/s | raw SDK msg/s | ours MB/s | raw MB/s | ours/raw (median) "
        "| ours/raw per run |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, size in SIZES.items():
        ours: list[dict[str, Any]] = []
        raw: list[dict[str, Any]] = []
        for _ in range(ns.repeats):
            raw.append(run_raw(size, ns.seconds, ns.client_queue))
            ours.append(run_ours(size, ns.seconds, raw[-1]["rate"], ns.client_queue))
            if ours[-1]["digest"] != raw[-1]["digest"]:
                raise SystemExit(f"bench_foxglove: the client got other bytes from us ({name})")
        ratio = statistics.median(o["rate"] for o in ours) / statistics.median(
            r["rate"] for r in raw
        )
        missed |= ratio < TARGET
        pairs = [o["rate"] / r["rate"] for o, r in zip(ours, raw, strict=True)]
        print(
            f"| {name} | {spread([o['rate'] for o in ours])} | {spread([r['rate'] for r in raw])}"
            f" | {statistics.median(o['mbps'] for o in ours):,.1f}"
            f" | {statistics.median(r['mbps'] for r in raw):,.1f} | {ratio:.2f}x"
            f" | {min(pairs):.2f}-{max(pairs):.2f}x |",
            flush=True,
        )
    print(f"load average after: {os.getloadavg()[0]:.1f}; target {TARGET}x raw")
    return 1 if ns.check and missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
