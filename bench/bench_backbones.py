"""Benchmark: the Zenoh backbone against raw Zenoh, and the ZeroMQ backbone beside them, in one
run on loopback.

    python bench/bench_backbones.py [--calls N] [--events N] [--runs R]

Calls: a generated stub's getData() to a server in another process, p50 of the round trip, (1)
over the Zenoh backbone (`--transport zenoh`, through the router in `miro naming --zenoh`), and
the same to a servant whose getData is marked `@nonblocking` (run without taking one of the
server's slots), (2) a raw Zenoh get() to a queryable in another process through the same
router, replying the same bytes (its callback replies at once, as plain Zenoh code does), and
(3) over the ZeroMQ backbone (`miro naming`, direct connection); the four rows' calls are taken
in turns, one of each. Events: ExampleEvents pushed by a supplier and counted by a keep-all
consumer of another session (both in this process, so both sides share one interpreter, as the
raw pairs do): events/s over the Zenoh backbone; raw Zenoh put/subscribe through the same
router, one put per event, of the event's CDR bytes encoded once beforehand and not decoded
("bytes"), or encoded for each put and decoded in the subscriber's callback with the same
generated code ("typed": what a Zenoh user needs to get the event a consumer's handler gets; the
callback runs it on Zenoh's thread, with no hand-off); and over ZeroMQ (a channel hosted by the
supplier's process). The raw publishers use congestion control BLOCK, as ours does for a
keep-all consumer, so that every event counted was sent. Everything is measured in interleaved
blocks, repeated R times (5); medians with their spread (min-max) and the load average. Issue
26's targets: calls at most 1.25x raw Zenoh get/reply, events at least 0.8x raw Zenoh
put/subscribe (printed against both raw rows).

Zenoh's default config sends messages of 3 KiB and more between processes of one host through
shared memory; the messages here are smaller, and each row says whether it was on
(`MIRO_ZENOH_SHM=0` turns it off for every session of the run, router included).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT), str(ROOT / "tests")]
os.environ.setdefault("MIRO_DISCOVERY", "0")

import Miro  # noqa: E402
import zenoh  # noqa: E402
from loopback import free_port, service_env  # noqa: E402

from miro_gen import (  # noqa: E402
    Client,
    EventChannelFactory,
    Server,
    StructuredEvent,
    StructuredPushConsumer,
    StructuredPushSupplier,
)
from miro_gen.transport.events import KEEP_ALL  # noqa: E402
from miro_gen.transport.zenoh.session import config, locator, shared_memory  # noqa: E402

NAMED = str(ROOT / "tests" / "procs" / "named_example.py")
RAW_ECHO = """
import json, sys, time, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
conf.insert_json5("scouting/multicast/enabled", "false")
s = zenoh.open(conf)
reply, head = bytes.fromhex(sys.argv[2]), bytes(16)
def answer(query):
    query.reply(query.key_expr, reply, attachment=head)
q = s.declare_queryable("bench/echo", answer)
print("READY", flush=True)
while True:
    time.sleep(3600)
"""
QUICK_SERVER = """
import sys
sys.path[:0] = [sys.argv.pop(1)]
import named_example
from miro_gen import nonblocking
class Quick(named_example.Example):
    @nonblocking
    def getData(self):
        return super().getData()
named_example.Example = Quick
named_example.main()
"""


def start(argv: list[str]) -> subprocess.Popen[str]:
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env=service_env())  # fmt: skip
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line.startswith(("READY", "naming service at")), line
    return proc


def naming(zenoh_backbone: bool) -> tuple[subprocess.Popen[str], str]:
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    extra = ["--zenoh"] if zenoh_backbone else []
    argv = [sys.executable, "-m", "miro_gen.cli.main", "naming", *extra, "--endpoint", endpoint,
            "--log-file", "none"]  # fmt: skip
    return start(argv), endpoint


def p50(samples: list[float]) -> float:
    return statistics.median(samples)


def time_calls(call: object, n: int) -> list[float]:
    clock, out = time.perf_counter, []
    for _ in range(n):
        t = clock()
        call()  # type: ignore[operator]
        out.append(clock() - t)
    return out


def time_interleaved(calls: list[Any], n: int) -> list[list[float]]:
    """Round trips of each of `calls`, `n` each, taken in turns (one call of each, the order
    reversed every other turn), so that a change of the machine's load hits every row alike:
    one row measured after the other moved their ratio by 0.3 between repeats."""
    clock = time.perf_counter
    out: list[list[float]] = [[] for _ in calls]
    pairs = list(zip(calls, out, strict=True))
    for i in range(n):
        for call, times in pairs if i % 2 else pairs[::-1]:
            t = clock()
            call()
            times.append(clock() - t)
    return out


class Counter(StructuredPushConsumer):
    def __init__(self, *args: object) -> None:
        super().__init__(*args, depth=KEEP_ALL)  # type: ignore[arg-type]  (counts every event)
        self.count = 0
        self.done = threading.Event()
        self.want = 0

    def push_structured_event(self, event: StructuredEvent) -> None:
        self.count += 1
        if self.count >= self.want:
            self.done.set()


def ours_events(
    supplier: StructuredPushSupplier, consumer: Counter, server: Server, n: int
) -> float:
    """Events/s: `n` events pushed (in turns of 100 on the supplier's reactor) until the
    consumer counted them all, or what it counted in a generous time."""
    consumer.count, consumer.want = 0, n
    consumer.done.clear()
    event = Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, 2.0))
    t = time.perf_counter()
    for i in range(0, n, 100):

        def turn() -> None:
            for _ in range(100):
                supplier.push("ExampleEvent", event)

        server.reactor().call_soon(turn)
        if i % 2000 == 0:
            time.sleep(0)  # let the reactor run
    consumer.done.wait(30)
    return consumer.count / (time.perf_counter() - t)


def raw_events(pub: object, got: list[int], done: threading.Event, payload: bytes, n: int) -> float:
    """Events/s: `n` puts of `payload` until the subscriber counted them all."""
    got[0] = 0
    done.clear()
    t = time.perf_counter()
    put = pub.put  # type: ignore[attr-defined]
    for _ in range(n):
        put(payload)
    done.wait(30)
    return got[0] / (time.perf_counter() - t)


def raw_typed_events(
    pub: object, got: list[int], done: threading.Event, event: Miro.ExampleEventIDL, n: int
) -> float:
    """Events/s: `n` events encoded and put until the subscriber decoded them all."""
    got[0] = 0
    done.clear()
    t = time.perf_counter()
    put = pub.put  # type: ignore[attr-defined]
    for _ in range(n):
        put(event.serialize())
    done.wait(30)
    return got[0] / (time.perf_counter() - t)


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):10.1f} ({min(values):.1f}-{max(values):.1f})"


def compare_pair(
    kinds: tuple[str, str],
    names: dict[str, str],
    stubs: dict[str, Any],
    events: dict[str, Any],
    args: argparse.Namespace,
    shm: str,
    label: str,
) -> None:
    """Calls' p50 and events/s of two set-ups of the Zenoh backbone (`kinds`: the baseline,
    then the one measured against it), interleaved in each of `args.runs` repeats, printed with
    their ratio (`label`: "other/base")."""
    base, other = kinds
    calls: dict[str, list[float]] = {k: [] for k in kinds}
    rates: dict[str, list[float]] = {k: [] for k in kinds}
    call_ratio, rate_ratio = [], []
    for run in range(args.runs):
        for kind in kinds if run % 2 == 0 else kinds[::-1]:
            calls[kind].append(p50(time_calls(stubs[kind].getData, args.calls)) * 1e6)
            sup_server, _, supplier, consumer = events[kind]
            rates[kind].append(ours_events(supplier, consumer, sup_server, args.events))
        call_ratio.append(calls[other][-1] / calls[base][-1])
        rate_ratio.append(rates[other][-1] / rates[base][-1])
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {args.runs} runs; "
          f"Zenoh shared memory {shm} (messages here are under 3 KiB)")  # fmt: skip
    print("call getData() p50 via the router, us (median, min-max)")
    for kind, values in calls.items():
        print(f"  {names[kind]:42} {spread(values)}  shm {shm}")
    print(f"  ratio {label} p50: {statistics.median(call_ratio):.2f} "
          f"(runs {', '.join(f'{r:.2f}' for r in call_ratio)})")  # fmt: skip
    print("events/s via the router (median, min-max)")
    for kind, values in rates.items():
        print(f"  {names[kind]:42} {spread(values)}  shm {shm}")
    print(f"  ratio {label} events/s: {statistics.median(rate_ratio):.2f} "
          f"(runs {', '.join(f'{r:.2f}' for r in rate_ratio)})")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--calls", type=int, default=1000, help="calls per row, block and run")
    ap.add_argument("--events", type=int, default=20000, help="events per row and run")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    shm = shared_memory(config("client"))
    zn, zendpoint = naming(True)
    mn, mendpoint = naming(False)
    procs = [zn, mn]
    try:
        procs.append(
            start(
                [sys.executable, NAMED, "--transport", "zenoh", "--naming", zendpoint, "-MNC", "r"]
            )
        )
        procs.append(start([sys.executable, NAMED, "--naming", mendpoint, "-MNC", "r"]))
        procs.append(
            start([sys.executable, "-c", QUICK_SERVER, str(Path(NAMED).parent), "--transport",
                   "zenoh", "--naming", zendpoint, "-MNC", "q"])
        )  # fmt: skip
        reply = Miro.ExampleStructIDL(1.0, 11.0).serialize()
        procs.append(start([sys.executable, "-c", RAW_ECHO, locator(zendpoint), reply.hex()]))
        zc = Client(["b", "--transport", "zenoh", "--naming", zendpoint])
        mc = Client(["b", "--naming", mendpoint])
        z_stub = zc.resolve_name("r/ExampleA", Miro.Example, wait=10)
        m_stub = mc.resolve_name("r/ExampleA", Miro.Example, wait=10)
        q_stub = zc.resolve_name("q/ExampleA", Miro.Example, wait=10)
        raw = zenoh.open(config("client", connect=locator(zendpoint)))
        header = bytes(24)

        def raw_get() -> None:
            for r in raw.get("bench/echo", payload=header, attachment=header):
                r.ok.payload.to_bytes()

        # events: two servers per backbone, supplier and consumer in separate sessions
        servers = {}
        for name, options in (("zenoh", ["--transport", "zenoh", "--naming", zendpoint]),
                              ("zmq", ["--naming", mendpoint])):  # fmt: skip
            sup_server = Server(["s", *options, "-MNC", f"s{name}"])
            con_server = Server(["c", *options, "-MNC", f"c{name}"])
            for s in (sup_server, con_server):
                threading.Thread(target=s.run, daemon=True).start()
            channel = EventChannelFactory(sup_server).create_channel("Bench")
            consumer = Counter(con_server.resolve_channel(f"s{name}/Bench"))
            consumer.set_subscriptions([("*", "ExampleEvent")])
            supplier = StructuredPushSupplier(channel)
            servers[name] = (sup_server, con_server, supplier, consumer)
        raw_got, raw_done = [0], threading.Event()
        raw_n = args.events
        decode = Miro.ExampleEventIDL.deserialize

        def raw_sample(sample: object) -> None:
            raw_got[0] += 1
            if raw_got[0] >= raw_n:
                raw_done.set()

        def raw_typed_sample(sample: object) -> None:
            decode(sample.payload.to_bytes())  # type: ignore[attr-defined]
            raw_got[0] += 1
            if raw_got[0] >= raw_n:
                raw_done.set()

        block = zenoh.CongestionControl.BLOCK
        raw_sub = raw.declare_subscriber("bench/ev", raw_sample)
        raw_typed_sub = raw.declare_subscriber("bench/typed", raw_typed_sample)
        raw_pub_session = zenoh.open(config("client", connect=locator(zendpoint)))
        raw_pub = raw_pub_session.declare_publisher("bench/ev", congestion_control=block)
        raw_typed_pub = raw_pub_session.declare_publisher("bench/typed", congestion_control=block)
        example = Miro.ExampleEventIDL(1, Miro.ExampleStructIDL(1.0, 2.0))
        payload = example.serialize()  # the bytes a raw Zenoh user would put
        time.sleep(1.0)
        for _ in range(200):  # warm up
            z_stub.getData(), q_stub.getData(), m_stub.getData(), raw_get()
        rows: dict[str, list[float]] = {
            k: [] for k in ("ours-zenoh", "ours-quick", "raw-zenoh", "ours-zmq")
        }
        ev: dict[str, list[float]] = {
            k: [] for k in ("ours-zenoh", "raw-zenoh", "raw-typed", "ours-zmq")
        }
        call_ratio, quick_ratio, event_ratio, typed_ratio = [], [], [], []
        for _ in range(args.runs):
            a, q, b, c = map(p50, time_interleaved(
                [z_stub.getData, q_stub.getData, raw_get, m_stub.getData], args.calls))  # fmt: skip
            rows["ours-zenoh"].append(a * 1e6)
            rows["ours-quick"].append(q * 1e6)
            rows["raw-zenoh"].append(b * 1e6)
            rows["ours-zmq"].append(c * 1e6)
            call_ratio.append(a / b)
            quick_ratio.append(q / b)
            sz, _cz, supz, conz = servers["zenoh"]
            e1 = ours_events(supz, conz, sz, args.events)
            e2 = raw_events(raw_pub, raw_got, raw_done, payload, args.events)
            e4 = raw_typed_events(raw_typed_pub, raw_got, raw_done, example, args.events)
            sm, _cm, supm, conm = servers["zmq"]
            e3 = ours_events(supm, conm, sm, args.events)
            ev["ours-zenoh"].append(e1)
            ev["raw-zenoh"].append(e2)
            ev["raw-typed"].append(e4)
            ev["ours-zmq"].append(e3)
            event_ratio.append(e1 / e2)
            typed_ratio.append(e1 / e4)
        load = os.getloadavg()
        on = "on" if shm else "off"
        print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {args.runs} runs; "
              f"Zenoh shared memory {on} (messages here are under 3 KiB)")  # fmt: skip
        print(f"{'call getData() p50, us (median, min-max)':44} {'':>10}")
        names = {"ours-zenoh": "miro-gen over Zenoh (via router)",
                 "ours-quick": "  the same, getData @nonblocking",
                 "raw-zenoh": "raw Zenoh get/reply (via router)",
                 "raw-typed": "raw Zenoh put/subscribe, typed (via router)",
                 "ours-zmq": "miro-gen over ZeroMQ (direct)"}  # fmt: skip
        for k, v in rows.items():
            print(f"  {names[k]:42} {spread(v)}  shm {on if k != 'ours-zmq' else 'n/a'}")
        for what, ratios in (("", call_ratio), (", @nonblocking", quick_ratio)):
            print(f"  ratio miro-gen/raw Zenoh p50{what}: {statistics.median(ratios):.2f} "
                  f"(runs {', '.join(f'{r:.2f}' for r in ratios)}; target <= 1.25)")  # fmt: skip
        print("events/s (median, min-max)")
        for k, v in ev.items():
            name = names[k].replace("get/reply", "put/subscribe, bytes")
            print(f"  {name:44} {spread(v)}  shm {on if 'zmq' not in k else 'n/a'}")
        for what, ratios in (("bytes", event_ratio), ("typed", typed_ratio)):
            print(f"  ratio miro-gen/raw Zenoh {what} events/s: {statistics.median(ratios):.2f} "
                  f"(runs {', '.join(f'{r:.2f}' for r in ratios)}; target >= 0.8)")  # fmt: skip
        for sup_server, con_server, _, _ in servers.values():
            sup_server.shutdown()
            con_server.shutdown()
        raw_sub.undeclare()
        raw_typed_sub.undeclare()
        zc.close()
        mc.close()
    finally:
        for p in procs:
            p.kill()
            p.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
