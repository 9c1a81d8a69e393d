"""A process that hosts an event channel, for the fault tests: a real host to kill and restart.

    python tests/procs/channel_host.py [common options] CHANNEL

Hosts CHANNEL (bound in its naming context), prints `READY` once it is bound, and serves until
SIGINT/SIGTERM (or is killed).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

from miro_gen import EventChannelFactory, Server  # noqa: E402


def main() -> None:
    server = Server(sys.argv)
    EventChannelFactory(server).create_channel(server.argv[1])
    server.reactor().call_soon(lambda: print("READY", flush=True))
    server.run()


if __name__ == "__main__":
    main()
