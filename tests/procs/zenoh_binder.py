"""Binds and looks up names at the Zenoh backbone's registry with this process's key, for the
tests of who binds what (tests/transport/test_zenoh_owners.py).

    python tests/procs/zenoh_binder.py NAMING bind NAME ...     # bind each NAME, one line each
    python tests/procs/zenoh_binder.py NAMING resolve NAME ...  # look each NAME up

`bind` binds each NAME as the service `binder` (its process's endpoint, a 60 s lease, not
renewed), through the naming client's stub for binding operations, and prints `BOUND NAME`
or `REFUSED NAME TYPE: MESSAGE` (the exception's one line). `resolve` prints `ENTRY NAME
ENDPOINT` or `NOTFOUND NAME`.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import MiroNaming  # noqa: E402

from miro_gen import Client  # noqa: E402
from miro_gen.exceptions import SystemException  # noqa: E402


def main() -> None:
    naming, what, *names = sys.argv[1:]
    client = Client(["binder", "--transport", "zenoh", "--naming", naming])
    if what == "bind":
        registry = client.naming.registry_stub(client.invoker, 5.0, owner=True)
        owner = MiroNaming.Owner("binder", f"run-{os.getpid()}")
        for name in names:
            entry = MiroNaming.Entry(name, "IDL:Miro/Example:1.0", "zenoh/%/binder", b"x", "")
            try:
                registry.bind_as(entry, owner, 60_000, False)
            except SystemException as e:
                print(f"REFUSED {name} {type(e).__name__}: {e.one_line()}", flush=True)
            except MiroNaming.AlreadyBound:
                print(f"REFUSED {name} AlreadyBound", flush=True)
            else:
                print(f"BOUND {name}", flush=True)
    elif what == "resolve":
        for name in names:
            try:
                entry = client.naming.registry.resolve(name)
            except MiroNaming.NotFound:
                print(f"NOTFOUND {name}", flush=True)
            else:
                print(f"ENTRY {name} {entry.endpoint}", flush=True)
    client.close()


if __name__ == "__main__":
    main()
