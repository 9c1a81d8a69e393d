"""A process's Zenoh session: opened once, from where its naming service is.

Every process but `miro naming --zenoh` is a Zenoh client of the router that the naming
service hosts (as rmw_zenoh's nodes are of their router): `--naming tcp://HOST:PORT` is the
router's `tcp/HOST:PORT`. Multicast scouting is off (nothing leaves loopback unless asked);
each process has its own session (its id names its objects: transport.zenoh.keys); the link
lease is the names' lease (3 s), so a cut link is noticed in about that time. With a key, the
link is mutual TLS, `tls/HOST:PORT` (transport.zenoh.security says when).

Shared memory: Zenoh's default sends messages of 3 KiB and more between processes of one host
through shared memory. `MIRO_ZENOH_SHM=0` turns it off, `1` on; the default is Zenoh's
(on). `shared_memory(config)` says which it is, for benches and logs.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import re
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from miro_gen.exceptions import TRANSIENT
from miro_gen.log import logger
from miro_gen.transport.tlsfiles import TlsFiles
from miro_gen.transport.zenoh import keys
from miro_gen.transport.zenoh.security import configure_tls, refused_hint, scheme

_log = logger("MIRO")

OPEN_RETRY = 0.2  # seconds between two attempts to reach the router
LINK_LEASE_MS = 3000  # a cut link is noticed after this (Zenoh's default: 10 s)
SHM_ENV = "MIRO_ZENOH_SHM"
_TCP = re.compile(r"^tcp://(?P<host>\[[^\]]+\]|[^:/]+):(?P<port>\d+)$")


def locator(naming: str, tls: TlsFiles | None = None) -> str:
    """The Zenoh locator of a naming address (`tcp://HOST:PORT` -> `tcp/HOST:PORT`, or
    `tls/HOST:PORT` with TLS files)."""
    m = _TCP.match(naming.strip())
    if m is None:
        raise ValueError(f"cannot make a Zenoh locator of {naming!r}: expected tcp://HOST:PORT")
    return f"{scheme(tls)}/{m.group('host')}:{m.group('port')}"


def shm_wanted() -> bool | None:
    """What MIRO_ZENOH_SHM asks for (None: Zenoh's default)."""
    value = os.environ.get(SHM_ENV, "")
    if value == "":
        return None
    return value not in ("0", "false", "no", "off")


def config(
    mode: str,
    *,
    connect: str | None = None,
    listen: str | None = None,
    tls: TlsFiles | None = None,
) -> Any:
    """A Zenoh config: `mode` client or router, connecting to or listening on one locator,
    with mutual TLS when `tls` is given (the locator is then `tls/...`)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if connect is not None:
        conf.insert_json5("connect/endpoints", json.dumps([connect]))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps([listen]))
    else:
        conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "true")
    conf.insert_json5("transport/link/tx/lease", str(LINK_LEASE_MS))
    shm = shm_wanted()
    if shm is not None:
        conf.insert_json5("transport/shared_memory/enabled", json.dumps(shm))
    if tls is not None:
        configure_tls(conf, tls, listening=listen is not None)
    return conf


def shared_memory(conf: Any) -> bool:
    """Whether a config sends large messages on one host through shared memory."""
    return bool(json.loads(conf.get_json("transport/shared_memory/enabled")))


_owners: dict[str, str] = {}  # session id -> its certificate's common name (open_client)


def identity(session: Any) -> str:
    """The identity of `session` in keys (transport.zenoh.keys): `<owner>/<zid>`, the owner
    the common name of the certificate it was opened with (none: `%`)."""
    zid = str(session.zid())
    return keys.identity(_owners.get(zid, ""), zid)


_callbacks: list[Any] = []  # subscribers and queryables whose callbacks are Python code
_callbacks_lock = threading.Lock()


def _undeclare_all() -> None:
    """Undeclare what still calls Python code when the interpreter exits: a subscriber or a
    queryable left declared keeps the process from ever ending (Zenoh's threads wait for the
    interpreter), and so does closing its session then."""
    with _callbacks_lock:
        entities, _callbacks[:] = list(_callbacks), []
    for entity in entities:
        with contextlib.suppress(zenoh.ZError):
            entity.undeclare()


atexit.register(_undeclare_all)


def direct(callback: Callable[[Any], object]) -> Any:
    """`callback` run on Zenoh's own thread, as a handler: no Python thread per subscriber or
    queryable (zenoh-python's default gives each one, which keeps a process from exiting
    while it is declared, and costs a thread switch per sample). Only for callbacks that
    never block and never call Zenoh: they append to a queue or hand over to the reactor."""
    return zenoh.handlers.Callback(callback, indirect=False)


def track(entity: Any) -> Any:
    """`entity` (a subscriber or a queryable with a Python callback), undeclared when the
    interpreter exits if it still is declared then."""
    with _callbacks_lock:
        _callbacks.append(entity)
    return entity


def untrack(entity: Any) -> None:
    """Undeclare `entity` (made with `track`) now."""
    with _callbacks_lock:
        if entity in _callbacks:
            _callbacks.remove(entity)
    with contextlib.suppress(zenoh.ZError):
        entity.undeclare()


def open_client(naming: str, wait: float | None = 0.0, tls: TlsFiles | None = None) -> Any:
    """A client session of the router at `naming` (tcp://HOST:PORT), over mutual TLS with
    `tls`, waiting up to `wait` seconds (None: no limit) for the router to be up, as a server
    waits for its naming service; then TRANSIENT. A router that refuses this session (TLS
    without a key of its CA, or no TLS) looks the same as one that is down: Zenoh says only
    that it could not connect, so the TRANSIENT says both."""
    target = locator(naming, tls)
    deadline = None if wait is None else time.monotonic() + wait
    said = False
    while True:
        try:
            session = zenoh.open(config("client", connect=target, tls=tls))
        except zenoh.ZError as e:
            if deadline is not None and time.monotonic() >= deadline:
                raise TRANSIENT(
                    f"cannot reach the Zenoh router at {target} (is `miro naming --zenoh` "
                    f"running? see --naming / MIRO_NAMING{refused_hint(tls)}): "
                    f"{str(e).split(' at ')[0].strip()}"
                ) from None
            if not said:
                # A server that waits on says so as loudly as one waiting for ZeroMQ's naming
                # service; a client's moment ends in its TRANSIENT anyway.
                say = _log.warning if wait is None or wait > 2.0 else _log.notice
                say("waiting for the Zenoh router at %s%s", target, refused_hint(tls))
                said = True
            time.sleep(OPEN_RETRY)
            continue
        if tls is not None:
            _owners[str(session.zid())] = tls.name
        return session
