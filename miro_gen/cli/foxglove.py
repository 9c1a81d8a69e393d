"""`miro foxglove`: serve the running robot to Foxglove and Lichtblick (miro_gen.foxglove)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from miro_gen.cli.eventargs import COMMON, make_server, resolve_or_wait, split_common
from miro_gen.foxglove import DEFAULT_BACKLOG, DEFAULT_PORT

EXTRA = "pip install 'miro-gen[foxglove]'"


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="miro foxglove",
        description="Serve the running robot over the Foxglove WebSocket protocol (subprotocol "
        "foxglove.sdk.v1): every offered event topic as a channel with its omgidl schema, the "
        "objects' operations as services (JSON), the services' parameters, and publishing "
        "into the event channel. Loopback only unless --tls-cert/--tls-key or --insecure. "
        "Needs the foxglove extra (" + EXTRA + "). " + COMMON,
    )
    add_listen_options(p)
    p.add_argument("--channel", default="EventChannel", metavar="NAME", help="default EventChannel")
    p.add_argument(
        "--refresh",
        type=float,
        default=1.0,
        metavar="S",
        help="seconds between looks for new topics, services and parameters (default 1)",
    )
    return p


def add_listen_options(p: argparse.ArgumentParser) -> None:
    """Where and how the WebSocket server listens (also `miro log play --foxglove`)."""
    p.add_argument(
        "--address",
        default="127.0.0.1",
        metavar="ADDR",
        help="the address to listen on (default 127.0.0.1; another needs TLS or --insecure)",
    )
    p.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        metavar="N",
        help=f"the WebSocket port (default {DEFAULT_PORT}; 0: any free one)",
    )
    p.add_argument("--tls-cert", metavar="PEM", help="serve wss:// with this certificate")
    p.add_argument("--tls-key", metavar="PEM", help="... and this private key (PKCS#8)")
    p.add_argument(
        "--client-queue",
        type=int,
        default=DEFAULT_BACKLOG,
        metavar="N",
        help=f"messages kept for a slow client, the oldest dropped beyond (default "
        f"{DEFAULT_BACKLOG})",
    )


def listen_of(p: argparse.ArgumentParser, ns: argparse.Namespace, insecure: bool) -> object:
    """The bridge's `Listen` from the options (usage errors for what does not fit)."""
    from miro_gen.foxglove.bridge import BridgeError, Listen

    def read(path: str | None) -> bytes | None:
        if path is None:
            return None
        try:
            return Path(path).read_bytes()
        except OSError as e:
            p.error(f"{path}: {e.strerror or e}")

    if not 0 <= ns.port <= 65535:
        p.error("--port takes 0 to 65535")
    listen = Listen(
        ns.address, ns.port, read(ns.tls_cert), read(ns.tls_key), insecure, ns.client_queue
    )
    try:
        listen.check()
    except BridgeError as e:
        p.error(str(e))
    return listen


def listen_at(p: argparse.ArgumentParser, text: str, argv: Sequence[str]) -> object:
    """The `Listen` of `[ADDR:]PORT` (`miro log play --foxglove`): loopback unless --insecure."""
    address, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        p.error(f"--foxglove takes [ADDR:]PORT, not {text!r}")
    ns = argparse.Namespace(
        address=address.strip("[]") or "127.0.0.1",
        port=number,
        tls_cert=None,
        tls_key=None,
        client_queue=DEFAULT_BACKLOG,
    )
    return listen_of(p, ns, insecure(argv))


def insecure(argv: Sequence[str]) -> bool:
    """Whether the common options say --insecure (checked by split_common before)."""
    from miro_gen.service.options import parse_common_options

    return bool(parse_common_options(list(argv))[0].insecure)


def sdk_missing() -> bool:
    """Whether the foxglove-sdk wheel is missing (said in one line)."""
    try:
        import foxglove  # noqa: F401
    except ImportError:
        print(f"miro foxglove: the Foxglove SDK is not installed: {EXTRA}", file=sys.stderr)
        return True
    return False


def foxglove_main(argv: Sequence[str]) -> int:
    prog = "miro foxglove"
    p = parser()
    ns = p.parse_args(split_common(p, argv))
    if not ns.refresh > 0:
        p.error("--refresh must be more than 0")
    if sdk_missing():
        return 1
    from miro_gen.foxglove.bridge import Bridge, BridgeError, Listen
    from miro_gen.live.remote import LiveError, Robot

    listen = listen_of(p, ns, insecure(argv))
    assert isinstance(listen, Listen)
    server = make_server(p, prog, argv)
    try:
        channel = resolve_or_wait(server, ns.channel, prog)
    except KeyboardInterrupt:
        server.close()
        return 130
    try:
        robot = Robot([prog, *argv])
    except LiveError as e:
        print(f"{prog}: {e}", file=sys.stderr)
        server.close()
        return 1
    try:
        bridge = Bridge(server, robot, channel, listen, ns.refresh)
    except BridgeError as e:  # the port is taken, a certificate the SDK refuses
        print(f"{prog}: {e}", file=sys.stderr)
        robot.close()
        server.close()
        return 1
    except BaseException:
        robot.close()
        server.close()
        raise
    scheme = "wss" if listen.cert is not None else "ws"
    print(
        f"{prog}: serving {channel.name} at {scheme}://{listen.address}:{bridge.port} "
        "(foxglove.sdk.v1)",
        file=sys.stderr,
        flush=True,
    )
    try:
        bridge.start()
        server.run()
    finally:
        bridge.close()
        robot.close()
    return 0
