"""Asks the naming service of the Zenoh backbone, for the fleet tests.

    python tests/procs/zenoh_probe.py NAMING list PREFIX     # the names under PREFIX
    python tests/procs/zenoh_probe.py NAMING call NAME N     # setData/getData N times
    python tests/procs/zenoh_probe.py NAMING rogue NAME      # answer for NAME's server

`--insecure` anywhere: the probe's session is in the clear beyond loopback (its key unused).

`rogue` declares a queryable on the key of the session that serves NAME and answers every
query there with a wrong value (saying `HEARD` on stderr); it prints READY and runs until
killed.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402

from miro_gen import Client  # noqa: E402


def main() -> None:
    insecure = ["--insecure"] if "--insecure" in sys.argv else []
    naming, what, arg, *more = [a for a in sys.argv[1:] if a != "--insecure"]
    client = Client(
        ["probe", "--transport", "zenoh", "--naming", naming, "-MNC", "base", *insecure]
    )
    if what == "list":
        for entry in client.naming.entries(arg):
            print(entry.name, entry.endpoint)
    elif what == "call":
        example = client.resolve_name(arg, Miro.Example, wait=10)
        for i in range(int(more[0])):
            example.setData(float(i), 1.0)
            assert example.getData() == Miro.ExampleStructIDL(float(i) + 1, 2.0)
        print("OK", flush=True)
    elif what == "rogue":
        import zenoh

        from miro_gen.transport.rpc import frames
        from miro_gen.transport.zenoh import keys

        entry = client.naming.resolve(arg)
        wrong = Miro.ExampleStructIDL(-1.0, -1.0).serialize()

        def answer(query: zenoh.Query) -> None:
            assert query.attachment is not None
            request = frames.decode_request(query.attachment.to_bytes())
            header = frames.reply_header(request.request_id, 0)
            query.reply(query.key_expr, wrong, attachment=header)
            sys.stderr.write("HEARD\n")  # (one short write: the test counts the calls heard)
            sys.stderr.flush()

        zid = keys.zid_of(entry.endpoint)
        assert zid is not None
        session = client.zenoh
        queryable = session.declare_queryable(keys.call_key(zid), answer)
        print("READY", flush=True)
        while True:
            time.sleep(1)
        del queryable
    client.close()


if __name__ == "__main__":
    main()
