"""A stranger to the naming service, for the attack tests: a process that binds, unbinds and
renews names that are not its own, under owners it makes up, as an attacker on the same
machine would (run as another user with `setpriv`, or as the same one).

    python naming_stranger.py ENDPOINT [--tcp] try NAME SERVICE
        one of each call against NAME, claiming to be SERVICE; one JSON line of outcomes
    python naming_stranger.py ENDPOINT [--tcp] poll NAME SERVICE
        bind NAME (taking over) every 20 ms until its standard input closes; prints STARTED,
        then one JSON line: tries, binds that succeeded, and the failures by kind
    python naming_stranger.py ENDPOINT [--tcp] fill PREFIX N
        bind N names PREFIX/0 ... under a new made-up owner each; one JSON line of counts

`--tcp`: over TCP even on the naming service's machine (not its Unix socket).
"""

from __future__ import annotations

import json
import sys
import threading
import time
import uuid
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import MiroNaming  # noqa: E402
import zmq  # noqa: E402

from miro_gen.exceptions import SystemException  # noqa: E402
from miro_gen.transport.naming.client import NamingClient  # noqa: E402
from miro_gen.transport.rpc.invoker import ZmqInvoker  # noqa: E402

POLL = 0.02


def outcome(call: object) -> str:
    try:
        result = call()  # type: ignore[operator]
    except MiroNaming.AlreadyBound as e:
        return f"AlreadyBound: {e.holder}"
    except MiroNaming.NotFound:
        return "NotFound"
    except SystemException as e:
        return f"{type(e).__name__}: {e.message}"
    return f"ok {result!r}" if result is not None else "ok"


def main() -> None:
    args = sys.argv[1:]
    endpoint = args.pop(0)
    tcp = args[0] == "--tcp"
    if tcp:
        args.pop(0)
    invoker = ZmqInvoker(zmq.Context())
    naming = NamingClient(invoker, endpoint, "stranger")
    if tcp:
        naming.owner_endpoint = endpoint
    registry = naming.registry_stub(invoker, 5.0, owner=True)
    what = args[0]
    if what == "try":
        name, service = args[1], args[2]
        who = MiroNaming.Owner(service, uuid.uuid4().hex)
        entry = MiroNaming.Entry(name, "IDL:Miro/Example:1.0", "tcp://10.66.6.6:666", b"evil", "")
        print(
            json.dumps(
                {
                    "bind": outcome(lambda: registry.bind_as(entry, who, 60_000, False)),
                    "take_over": outcome(lambda: registry.bind_as(entry, who, 60_000, True)),
                    "unbind": outcome(lambda: registry.unbind_as(name, who)),
                    "renew": outcome(lambda: registry.renew_as(who, [name], 60_000)),
                }
            ),
            flush=True,
        )
    elif what == "poll":
        name, service = args[1], args[2]
        entry = MiroNaming.Entry(name, "IDL:Miro/Example:1.0", "tcp://10.66.6.6:666", b"evil", "")
        done = threading.Event()
        threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
        counts: Counter[str] = Counter()
        print("STARTED", flush=True)
        while not done.wait(POLL):
            who = MiroNaming.Owner(service, uuid.uuid4().hex)
            result = outcome(lambda w=who: registry.bind_as(entry, w, 60_000, True))  # type: ignore[misc]
            counts[result.split(":")[0]] += 1
        print(json.dumps({"tries": sum(counts.values()), "outcomes": counts}), flush=True)
    elif what == "fill":
        prefix, n = args[1], int(args[2])
        counts = Counter()
        start = time.monotonic()
        for i in range(n):
            who = MiroNaming.Owner(f"made-up/{i}", uuid.uuid4().hex)
            entry = MiroNaming.Entry(
                f"{prefix}/{i}", "IDL:Miro/Example:1.0", "tcp://10.66.6.6:666", b"k" * 8, ""
            )
            result = outcome(
                lambda e=entry, w=who: registry.bind_as(e, w, 60_000, False)  # type: ignore[misc]
            )
            counts[result.split(":")[0]] += 1
        print(
            json.dumps({"outcomes": counts, "seconds": time.monotonic() - start}),
            flush=True,
        )
    invoker.close()


if __name__ == "__main__":
    main()
