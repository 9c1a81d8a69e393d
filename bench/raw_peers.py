"""What the benches stand on: a free loopback port (every bench that starts a naming service or
a raw peer), and a raw Zenoh peer's configuration with multicast scouting off, for the event
benches' baselines (nothing leaves loopback)."""

from __future__ import annotations

import socket
from typing import Any


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def zenoh_config(listen: str | None, connect: str | None) -> Any:
    """A raw Zenoh peer listening on `listen` and connecting to `connect` (either may be None)."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", f'["{listen}"]' if listen else "[]")
    conf.insert_json5("connect/endpoints", f'["{connect}"]' if connect else "[]")
    return conf
