"""`miro naming` (the naming service, optionally hosting event channels), `miro nslist` (what it
holds, as a tree) and `miro nsunbind` (free names kept for a server of yours that stopped)."""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import signal
import socket
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import MiroNaming
import zmq

from miro_gen import log
from miro_gen.exceptions import SystemException
from miro_gen.service.options import DEFAULT_NAMING, UsageError, byte_size, naming_endpoint
from miro_gen.transport import sockets
from miro_gen.transport.addresses import server_addresses
from miro_gen.transport.events.channels import CHANNEL_REPO_ID, ChannelHost
from miro_gen.transport.local import naming_socket
from miro_gen.transport.naming.client import (
    DEFAULT_HOLD,
    DEFAULT_MAX_NAMES,
    DEFAULT_QUOTA,
    check_name,
    naming_errors,
)
from miro_gen.transport.naming.owners_log import LogError, default_path
from miro_gen.transport.naming.service import NamingService
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.rpc.invoker import ZmqInvoker

if TYPE_CHECKING:  # (the CORBA doors load only with --iiop-endpoint)
    from miro_gen.corba.notify import NotifyChannel
    from miro_gen.corba.server import IIOPServer
    from miro_gen.transport.events.notify_door import NotifyDoor
    from miro_gen.transport.naming.cosnaming_door import RegistryTable

# What a stranger may do with a naming service served --insecure beyond loopback
NAMING_SERVES = "list, resolve and bind names, and publish and subscribe on its event channels"

_log = log.logger("MIRO")


def naming_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro naming",
        description="Run the naming service: servers bind their objects' names in it, "
        "clients resolve them. Names of servers that stop renewing their leases expire.",
    )
    p.add_argument(
        "--endpoint",
        default=os.environ.get("MIRO_NAMING") or DEFAULT_NAMING,
        help=f"where to serve (default $MIRO_NAMING, where services look for it, else "
        f"{DEFAULT_NAMING}, this machine only; for other hosts use this machine's address, "
        "or tcp://0.0.0.0:2809 for every interface)",
    )
    p.add_argument(
        "--channel",
        action="append",
        default=[],
        metavar="NAME",
        help="also host the event channel NAME (bound as NAME, found from any naming context), "
        "so that it outlives its suppliers; may be repeated",
    )
    p.add_argument(
        "--host",
        help="the address to advertise for hosted channels when --endpoint listens on all "
        "interfaces",
    )
    p.add_argument(
        "--keys",
        default=os.environ.get("MIRO_KEYS") or None,
        metavar="FILE",
        help="the robot's or fleet's key (`miro keys new`; default $MIRO_KEYS): only processes "
        "holding it may connect, and everything is encrypted (CURVE; with --zenoh, mutual TLS "
        "with the key's certificates). Needed when --endpoint "
        f"is not loopback, unless {sockets.DEFAULT_KEY} exists or --insecure is given",
    )
    p.add_argument(
        "--insecure",
        action="store_true",
        help="serve beyond loopback without a key or encryption: anyone who can connect may "
        "list, resolve and bind names and use the event channels, and anyone on the way may "
        "read and change what is said (it says so as it starts; docs/SECURITY.md)",
    )
    p.add_argument(
        "--quota",
        type=int,
        default=DEFAULT_QUOTA,
        metavar="N",
        help=f"names one user of this machine, or one other host, may hold (default "
        f"{DEFAULT_QUOTA})",
    )
    p.add_argument(
        "--hold",
        type=float,
        default=DEFAULT_HOLD,
        metavar="SECONDS",
        help="how long the names of a server that stopped without unbinding stay kept for its "
        f"user or host (default {DEFAULT_HOLD:g})",
    )
    p.add_argument(
        "--log-file",
        metavar="FILE",
        help="the log of owners, read back at start so that a restart hands no name to "
        "another user (default $XDG_STATE_HOME/miro/naming-PORT.log); `none`: keep nothing",
    )
    p.add_argument(
        "--max-names",
        type=int,
        default=DEFAULT_MAX_NAMES,
        metavar="N",
        help=f"names in all (default {DEFAULT_MAX_NAMES})",
    )
    p.add_argument(
        "--max-message-size",
        metavar="BYTES",
        default=os.environ.get("MIRO_MAX_MESSAGE_SIZE") or None,
        help="the largest message accepted (default 8M; K, M, G suffixes); a larger one "
        "closes its connection",
    )
    p.add_argument(
        "--max-connections",
        type=int,
        default=sockets.DEFAULT_MAX_CONNECTIONS,
        metavar="N",
        help=f"connections per socket (default {sockets.DEFAULT_MAX_CONNECTIONS})",
    )
    p.add_argument(
        "--iiop-endpoint",
        metavar="HOST:PORT",
        help="also answer CORBA clients at HOST:PORT (IIOP, loopback unless --insecure): "
        "CosNaming over the same names, for C++ services started with -ORBInitRef "
        "NameService=corbaloc::HOST:PORT/NameService, and each --channel as a "
        "CosNotifyChannelAdmin::EventChannel (docs/CORBA.md)",
    )
    p.add_argument("-MLL", "--log-level", type=int, default=5, help="Miro log level (default 5)")
    p.add_argument(
        "--no-announce",
        action="store_true",
        help="do not announce this naming service on the network (multicast DNS), so that "
        "processes without --naming cannot find it",
    )
    p.add_argument(
        "-m",
        dest="multicast",
        type=int,
        choices=(0, 1),
        help="the manual's Naming_Service switch: -m 1 announces (the default), -m 0 does not",
    )
    p.add_argument(
        "-ORBEndpoint",
        "-ORBEndPoint",
        dest="orb_endpoint",
        metavar="iiop://HOST:PORT",
        help="the manual's spelling of --endpoint",
    )
    p.add_argument(
        "--zenoh",
        action="store_true",
        help="the Zenoh backbone's naming service: a Zenoh router listening at --endpoint "
        "with the name registry beside it, for services run with --transport zenoh; with a "
        "key, mutual TLS: only sessions holding a certificate of its CA get in "
        "(docs/FLEET.md)",
    )
    p.add_argument(
        "--per-robot",
        metavar="ROBOT,...",
        action="append",
        default=[],
        help="with --zenoh and a key: the router lets each ROBOT's certificate (`miro keys new "
        "ROBOT --ca FLEET`) declare, put and reply only under that robot's own keys and bind "
        "names only in its context (ROBOT/...), the certificate of its own key everything, "
        "and any other nothing (Zenoh's access control; docs/FLEET.md)",
    )
    p.add_argument(
        "--list-announced",
        action="store_true",
        help="list the naming services announced on this network, whether each answers and "
        "why not (as miro doctor does), and exit",
    )
    ns = p.parse_args(argv)
    if ns.list_announced:
        from miro_gen.cli.doctor import doctor_main

        return doctor_main([])
    if ns.orb_endpoint:
        ns.endpoint = _iiop_endpoint(p, ns.orb_endpoint)
    announce = not ns.no_announce and ns.multicast != 0
    if ns.quota < 1 or ns.max_names < 1 or ns.max_connections < 1:
        p.error("--quota, --max-names and --max-connections take a number from 1 up")
    if not 0 <= ns.hold < float("inf"):
        p.error("--hold takes a number of seconds, 0 or more")
    for name in ns.channel:
        try:
            check_name(name)
        except MiroNaming.InvalidName:
            p.error(f"--channel {name!r} is not a valid name")
    try:
        endpoint = naming_endpoint(ns.endpoint)
        if ns.host:
            server_addresses(endpoint, ns.host)  # checks that it is an address of this machine
        size = None
        if ns.max_message_size is not None:
            size = byte_size(ns.max_message_size, "--max-message-size")
        log.configure(ns.log_level)  # (before the policy: --insecure warns what it opens)
        if ns.zenoh:
            from miro_gen.transport.zenoh.security import tls_for

            tls = tls_for(
                keys=ns.keys,
                insecure=ns.insecure,
                binds=sockets.endpoint_host(endpoint),
                serves=NAMING_SERVES,
            )
        else:
            policy = sockets.policy_for(
                keys=ns.keys,
                insecure=ns.insecure,
                max_message_size=size,
                binds=sockets.endpoint_host(endpoint),
                serves=NAMING_SERVES,
            )
    except UsageError as e:
        p.error(str(e))
    robots = [r.strip() for given in ns.per_robot for r in given.split(",") if r.strip()]
    if ns.per_robot and not (ns.zenoh and tls is not None and robots):
        p.error(
            "--per-robot takes robots' names, and needs --zenoh and a key (mutual TLS: the "
            "router tells robots by their certificates); give --keys FILE"
        )
    if ns.zenoh:
        from miro_gen.cli.naming_zenoh import zenoh_naming

        log_path = ns.log_file or default_path(endpoint)
        return zenoh_naming(ns, endpoint, None if log_path == "none" else log_path, tls, robots)
    policy = dataclasses.replace(policy, max_connections=ns.max_connections)
    if ns.channel and not ns.host and re.search(r"://(0\.0\.0\.0|\*):", endpoint):
        p.error(
            "--channel with an --endpoint on every interface needs --host ADDRESS: the "
            "address other hosts reach the channel at"
        )
    reactor = Reactor(zmq.Context.instance())
    sockets.configure(reactor.context, policy)
    invoker = ZmqInvoker(reactor.context)
    log_path = ns.log_file or default_path(endpoint)
    try:
        service = NamingService(
            reactor,
            invoker,
            endpoint,
            ns.host,
            ns.quota,
            ns.max_names,
            hold=ns.hold,
            log_path=None if log_path == "none" else log_path,
        )
    except zmq.ZMQError as e:
        local = naming_socket(endpoint)
        also = f" and {local}" if local else ""
        print(f"miro naming: cannot serve on {endpoint}{also}: {e}", file=sys.stderr)
        return 1
    except LogError as e:
        print(f"miro naming: {e}", file=sys.stderr)
        return 1
    corba = None
    if ns.iiop_endpoint:
        try:
            corba = _serve_corba(ns.iiop_endpoint, ns.insecure, reactor, invoker, service)
        except UsageError as e:
            service.close()
            p.error(str(e))
        except SystemException as e:  # cannot listen there (in use, not an address)
            service.close()
            print(f"miro naming: {e.message}", file=sys.stderr)
            return 1
    channels = [_host_channel(service, name, corba) for name in ns.channel]
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: reactor.stop())
    bound = service.adapter.bound
    every = "://0.0.0.0:" in bound
    note = " (every interface: other hosts use this machine's address)" if every else ""
    if policy.keys is not None:
        note += f"; CURVE with the key {policy.keys.path}"
    elif ns.insecure and not sockets.is_loopback(sockets.endpoint_host(bound)):
        note += "; --insecure: in the clear, open to anyone who can reach it"
    if service.log is None:
        note += "; no log of owners: after a restart, names go to whoever binds first"
    lines = [f"naming service at {bound}{note}"]
    if corba is not None:
        lines.append(f"CosNaming at corbaloc::{corba.address}/NameService")
    lines += [f"event channel {n}" for n in ns.channel]
    # Said once the reactor runs: a signal from whoever waited for these lines then stops it.
    reactor.call_soon(lambda: print("\n".join(lines), flush=True))
    restored = service.restored
    if restored.bindings or restored.kept:
        reactor.call_soon(
            lambda: _log.notice(
                "%d names read back from %s (%d kept for servers that stopped)",
                restored.bindings + restored.kept,
                log_path,
                restored.kept,
            )
        )
    announcer = None
    if announce and not re.search(r"://(127\.|localhost)", bound):
        from miro_gen.transport.naming.discovery import Announcer

        announcer = Announcer(bound)
    reactor.run()
    if announcer is not None:
        announcer.close()
    for channel in channels:
        channel.close()
    if corba is not None:
        corba.close()
    service.close()
    reactor.close()
    return 0


def _iiop_endpoint(p: argparse.ArgumentParser, text: str) -> str:
    """`-ORBEndpoint iiop://HOST:PORT` (TAO's, as the manual writes it) as tcp://HOST:PORT."""
    m = re.match(r"^iiop://(?:\d+\.\d+@)?([^:/]+):(\d+)/?$", text.strip())
    if not m:
        p.error(f"-ORBEndpoint takes iiop://HOST:PORT, not {text!r}")
    return f"tcp://{m.group(1)}:{m.group(2)}"


def _host_channel(service: NamingService, name: str, corba: CorbaDoors | None) -> ChannelHost:
    """Host the event channel `name` in this process and bind it, lease-free, in `service`
    (with its Notification door when CORBA clients are served)."""
    host = _channel_host(service)
    entry = MiroNaming.Entry(
        name, CHANNEL_REPO_ID, host.supplier_endpoint, host.consumer_endpoint.encode(), ""
    )
    if corba is not None:
        entry = corba.open_door(name, host).entry()
    service.registry.keep(entry)
    return host


def _channel_host(service: NamingService) -> ChannelHost:
    """A channel hosted in this process, bound and advertised as the naming service is."""
    bound = service.adapter.bound
    bind_host = bound.split("://", 1)[1].rsplit(":", 1)[0]
    advertise = service.endpoint.split("://", 1)[1].rsplit(":", 1)[0]
    return ChannelHost(service.adapter.reactor.context, bind_host, advertise)


class CorbaDoors:
    """What `miro naming --iiop-endpoint` serves to CORBA clients: CosNaming over its names,
    and the Notification doors of the channels it hosts (transport.naming.cosnaming_door,
    transport.events.notify_door)."""

    def __init__(
        self, server: IIOPServer, reactor: Reactor, service: NamingService, names: RegistryTable
    ) -> None:
        from miro_gen.corba.notify.wire import EVENT_CHANNEL_FACTORY
        from miro_gen.transport.events.notify_door import FACTORY_KEY, serve_factory
        from miro_gen.transport.naming.cosnaming_door import RENEW_EVERY

        self.server = server
        self.reactor = reactor
        self.service = service
        self.address = f"{server.host}:{server.port}"
        self.doors: list[NotifyDoor] = []
        self._made = 0
        self._timer = reactor.schedule_timer(RENEW_EVERY, RENEW_EVERY, names.renew)
        self.factory = serve_factory(server, self._make)
        ior = self.factory.reference()
        service.registry.keep(
            MiroNaming.Entry(FACTORY_KEY, EVENT_CHANNEL_FACTORY, ior.to_string(), b"", "")
        )

    def open_door(self, name: str, host: ChannelHost) -> NotifyDoor:
        from miro_gen.transport.events.channels import EventChannel
        from miro_gen.transport.events.notify_door import NotifyDoor

        channel = EventChannel(
            name, host.supplier_endpoint, host.consumer_endpoint, self.reactor, "", host
        )
        door = NotifyDoor(channel, self.server, self.server.invoker, name, self.factory)
        self.doors.append(door)
        return door

    def _make(self, qos: dict[str, Any], admin: dict[str, Any]) -> NotifyChannel:
        """A channel a CORBA client asks the factory for: both doors, bound nowhere."""
        self._made += 1
        host = _channel_host(self.service)
        door = self.open_door(f"NotifyChannel/{self._made}", host)
        door.notify.destroyable = True
        door.notify.core.qos, door.notify.core.admin = qos, admin
        door.notify.on_close += [door.zmq.close, host.close]  # destroyed, or at the end
        return door.notify

    def close(self) -> None:
        self.reactor.cancel_timer(self._timer)
        for door in self.doors:
            door.close()
        self.server.close()


def _serve_corba(
    endpoint: str, insecure: bool, reactor: Reactor, invoker: ZmqInvoker, service: NamingService
) -> CorbaDoors:
    """Serve CORBA clients at `endpoint` (HOST:PORT): UsageError when it cannot be."""
    from miro_gen.corba.client import IIOPInvoker
    from miro_gen.service.iiop import serve_iiop
    from miro_gen.service.options import CommonOptions, iiop_endpoint
    from miro_gen.transport.naming.cosnaming_door import serve_cosnaming

    host, _, port = iiop_endpoint(endpoint, "--iiop-endpoint").rpartition(":")
    host = host.strip("[]") or "0.0.0.0"
    iiop = IIOPInvoker(invoker)
    options = CommonOptions(insecure=insecure)
    advertise = socket.gethostname() if host in ("0.0.0.0", "::") else host
    server = serve_iiop(iiop, options, host, advertise, int(port))
    iiop.server = server
    return CorbaDoors(server, reactor, service, serve_cosnaming(service.registry, server))


def nslist_main(argv: Sequence[str]) -> int:
    from miro_gen.service.server import Client

    p = argparse.ArgumentParser(
        prog="miro nslist",
        description="Print the names bound in the naming service, as a tree (the manual's "
        "nslist). Accepts the common options: --naming, -ORBInitRef NameService=...",
    )
    p.add_argument("prefix", nargs="?", default="", help="only names under this path")
    try:
        client = Client(["miro nslist", *argv])
    except UsageError as e:
        p.error(str(e))
    except SystemException as e:  # the Zenoh router is down, or refuses this session
        print(f"miro nslist: {e.message}", file=sys.stderr)
        return 1
    ns = p.parse_args(client.argv[1:])
    try:
        with naming_errors(client.options.naming, "list names"):
            # Page by page; a CORBA naming service's names are walked (corba.naming).
            entries = client.naming.entries(ns.prefix)
    except SystemException as e:
        print(f"miro nslist: {e.message}", file=sys.stderr)
        return 1
    finally:
        client.close()
    shown: set[tuple[str, ...]] = set()
    for entry in entries:
        parts = entry.name.split("/")
        for depth in range(len(parts) - 1):
            if tuple(parts[: depth + 1]) not in shown:
                shown.add(tuple(parts[: depth + 1]))
                print("  " * depth + parts[depth] + "/")
        print("  " * (len(parts) - 1) + f"{parts[-1]}  ({entry.repo_id} at {entry.endpoint})")
    if not entries:
        print("(no names bound)")
    return 0


def nsunbind_main(argv: Sequence[str]) -> int:
    import uuid

    from miro_gen.service.server import Client

    p = argparse.ArgumentParser(
        prog="miro nsunbind",
        description="Free names that the naming service keeps for a server of yours that "
        "stopped without unbinding them. After its lease ends, such a name stays kept for its "
        "user (or host) and service for an hour (`miro naming --hold`), so that no stranger "
        "takes it between a crash and a restart; a service that was renamed, or moved to "
        "another program, gets it once it is freed. Live names are their servers' to unbind. "
        "Accepts the common options: --naming, -MNC.",
    )
    p.add_argument("names", nargs="+", metavar="NAME", help="a path, or a name in -MNC")
    try:
        client = Client(["miro nsunbind", *argv])
    except UsageError as e:
        p.error(str(e))
    except SystemException as e:  # the Zenoh router is down, or refuses this session
        print(f"miro nsunbind: {e.message}", file=sys.stderr)
        return 1
    ns = p.parse_args(client.argv[1:])
    if not hasattr(client.naming, "registry_stub"):
        client.close()
        p.error("a CORBA naming service keeps no names for stopped servers")
    registry = client.naming.registry_stub(client.invoker, 5.0, owner=True)
    who = MiroNaming.Owner("miro-nsunbind", uuid.uuid4().hex)
    status = 0
    try:
        for name in ns.names:
            full = client.naming.full_name(name)
            try:
                with naming_errors(client.options.naming, f"unbind {full}"):
                    registry.unbind_as(full, who)
                print(f"freed {full}")
            except MiroNaming.NotFound:
                print(
                    f"miro nsunbind: {full} is not kept for you (a live name is its server's to "
                    "unbind; one kept for another user or host is theirs)",
                    file=sys.stderr,
                )
                status = 1
            except MiroNaming.InvalidName:
                print(f"miro nsunbind: {name!r} is not a valid name", file=sys.stderr)
                status = 1
    except SystemException as e:
        print(f"miro nsunbind: {e.message}", file=sys.stderr)
        return 1
    finally:
        client.close()
    return status
