"""Which security a Zenoh session gets, with ZeroMQ's defaults (docs/SECURITY.md), and its
config: mutual TLS with the robot's or fleet's key (transport.tlsfiles).

* on loopback: plain TCP, unless a key is given;
* beyond loopback (the router listens, or a session connects, elsewhere): TLS with the key
  (`--keys`, `MIRO_KEYS`, else the default key when it exists); without one, a one-line
  UsageError naming `--keys` and `--insecure`;
* `--insecure`: plain TCP, with the warnings ZeroMQ gives (what it opens).

With TLS the router listens on `tls/HOST:PORT` and requires a client certificate signed by
its CA (`enable_mtls`): a session without one, or with one of another CA, or without TLS,
is refused at the handshake, before it can declare anything ("no key, no entry"). Sessions
check the router's certificate against the same CA. Host names are not checked
(`verify_name_on_connect` off): a key names a robot or a fleet, not a host, as CURVE's does.
"""

from __future__ import annotations

import json
import os
from typing import Any

from miro_gen.transport import sockets
from miro_gen.transport.keyfiles import DEFAULT_KEY
from miro_gen.transport.tlsfiles import TlsFiles, has_tls, read_tls
from miro_gen.transport.usage import UsageError

_TLS = "transport/link/tls/"


def tls_for(
    *,
    keys: str | None,
    insecure: bool,
    binds: str | None = None,
    talks_to: str | None = None,
    serves: str = sockets.SERVES,
) -> TlsFiles | None:
    """The TLS files of a process whose options say `keys` and `insecure`, that listens on
    `binds` (the router) or connects to `talks_to` (a client), both hosts; None for plain
    TCP. Warns, as ZeroMQ's policy does, what `--insecure` opens (`serves`: what a stranger
    may then do with what it serves)."""
    wide_bind = binds if binds is not None and not sockets.stays_here(binds, True) else None
    wide_peer = (
        talks_to if talks_to is not None and not sockets.stays_here(talks_to, False) else None
    )
    if insecure:
        for line in sockets.insecure_exposure(keys, wide_bind, wide_peer, serves):
            sockets.say_once(line)
        return None
    if keys:
        return read_tls(keys)
    if wide_bind is None and wide_peer is None:
        return None
    default = os.path.expanduser(DEFAULT_KEY)
    if os.path.exists(default) or has_tls(default):
        return read_tls(default, "the default key")
    what = f"listens on {wide_bind}" if wide_bind is not None else f"talks to {wide_peer}"
    raise UsageError(
        f"this process {what}, beyond this machine, over Zenoh: give the robot's or fleet's "
        "key with --keys FILE (or MIRO_KEYS; make one with `miro keys new`), so that only "
        "processes holding it get in (TLS), or --insecure to let in anyone who can connect, "
        "in the clear"
    )


def scheme(tls: TlsFiles | None) -> str:
    """The Zenoh locator scheme of a link with (`tls`) or without TLS (`tcp`)."""
    return "tcp" if tls is None else "tls"


def configure_tls(conf: Any, tls: TlsFiles, *, listening: bool) -> None:
    """Mutual TLS with `tls` on `conf`: a router's listener or a client's connection."""
    side = "listen" if listening else "connect"
    conf.insert_json5(_TLS + "root_ca_certificate", json.dumps(tls.ca))
    conf.insert_json5(_TLS + f"{side}_certificate", json.dumps(tls.certificate))
    conf.insert_json5(_TLS + f"{side}_private_key", json.dumps(tls.private_key))
    conf.insert_json5(_TLS + "enable_mtls", "true")
    conf.insert_json5(_TLS + "verify_name_on_connect", "false")


def refused_hint(tls: TlsFiles | None) -> str:
    """Why a router that is up may still refuse this session, for the TRANSIENT it gets."""
    if tls is None:
        return (
            "; a router that serves with a key (TLS) refuses sessions without it: give --keys FILE"
        )
    return (
        f"; over TLS with the key {tls.name}: the router refuses a certificate its CA did not "
        "sign (another fleet's key), and this process a router whose certificate is not of "
        f"its CA ({tls.ca})"
    )
