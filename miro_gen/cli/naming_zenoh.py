"""`miro naming --zenoh`: the Zenoh router and the name registry in this process
(transport.zenoh.registry), until SIGINT or SIGTERM."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence

import zmq

from miro_gen import log
from miro_gen.transport import sockets
from miro_gen.transport.naming.owners_log import LogError
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.tlsfiles import TlsFiles

_log = log.logger("MIRO")


def zenoh_naming(
    ns: argparse.Namespace,
    endpoint: str,
    log_path: str | None,
    tls: TlsFiles | None = None,
    robots: Sequence[str] = (),
) -> int:
    """Serve names beside a Zenoh router listening at `endpoint` (tcp://HOST:PORT; with `tls`,
    mutual TLS at tls/HOST:PORT; with `robots`, each robot's certificate allowed only its own
    keys: transport.zenoh.access), with the options `miro naming` parsed (`ns`); the exit
    status."""
    try:
        import zenoh
    except ImportError:
        print(
            "miro naming: --zenoh needs the Zenoh wheel: pip install 'miro-gen[zenoh]'",
            file=sys.stderr,
        )
        return 1
    from miro_gen.transport.zenoh.registry import ZenohNaming

    reactor = Reactor(zmq.Context.instance())
    try:
        service = ZenohNaming(
            reactor,
            endpoint,
            ns.quota,
            ns.max_names,
            hold=ns.hold,
            log_path=log_path,
            tls=tls,
            robots=robots,
        )
    except zenoh.ZError as e:
        why = str(e).split(" at /")[0]  # (Zenoh's errors end with the Rust source's place)
        print(f"miro naming: cannot run a Zenoh router at {endpoint}: {why}", file=sys.stderr)
        return 1
    except LogError as e:
        print(f"miro naming: {e}", file=sys.stderr)
        return 1
    for name in ns.channel:
        service.keep_channel(name)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: reactor.stop())
    shm = "on" if service.shared_memory else "off"
    note = f" (Zenoh router {service.zid}; shared memory {shm})"
    if tls is not None:
        note += (
            f"; mutual TLS at {service.locator} with the key {tls.name}: only sessions whose "
            f"certificate its CA ({tls.ca}) signed get in"
        )
        if robots:
            note += (
                f"; access per robot: {', '.join(robots)} only their own keys, and names "
                f"in their own contexts, {tls.name} everything, any other certificate nothing"
            )
    elif ns.insecure and not sockets.is_loopback(sockets.endpoint_host(endpoint)):
        note += "; --insecure: in the clear, open to anyone who can reach it"
    if service.log is None:
        note += "; no log of owners: after a restart, names go to whoever binds first"
    lines = [f"naming service at {endpoint}{note}", *(f"event channel {n}" for n in ns.channel)]
    reactor.call_soon(lambda: print("\n".join(lines), flush=True))
    announcer = None
    if (
        not ns.no_announce
        and ns.multicast != 0
        and not sockets.is_loopback(sockets.endpoint_host(endpoint))
    ):  # (transport.naming.discovery: the record says where the router listens)
        from miro_gen.transport.naming.discovery import Announcer

        announcer = Announcer(endpoint, zenoh=service.locator)
    try:
        reactor.run()
    finally:
        if announcer is not None:
            announcer.close()
        service.close()
        reactor.close()
    return 0
