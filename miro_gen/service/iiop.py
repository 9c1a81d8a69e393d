"""What a `Server` or `Client` does differently when it talks to the CORBA world (its IIOP side).

`corba_for(client)` looks at the common options: a naming-service URL that turns out to be a
CORBA naming service (`miro_gen.corba.naming.decide`), or `--iiop-endpoint`. Then the process
gets an IIOP invoker (which hands references that are not CORBA ones to the ZeroMQ invoker),
and a server an IIOP listener: `add_to_name_service` serves the servant over IIOP under its full
name as object key (`robot1/ExampleA`: persistent when the port is fixed, and reachable as
`corbaloc:iiop:HOST:PORT/robot1/ExampleA`) and binds its IOR in the CORBA naming service, or,
with a ZeroMQ naming service and `--iiop-endpoint`, serves it over both.

IIOP has neither keys nor encryption, so it follows the line CURVE is drawn at
(docs/SECURITY.md) with nothing to fall back on: a process serves IIOP on loopback, and talks
IIOP to a CORBA naming service on loopback, unless `--insecure`. Otherwise it stops at start-up
with a one-line error (`UsageError`) that says what is refused and names `--insecure`; with
`--insecure` it says what it opens. A CORBA peer on this machine that advertises another of the
machine's addresses (omniORB's default) is served on loopback (`iiop_addresses`).
"""

from __future__ import annotations

import socket
import threading
from typing import TYPE_CHECKING, Protocol

import MiroNaming

from miro_gen.corba.client import IIOPInvoker
from miro_gen.corba.ior import IOR, CorbaRef, ref_from_ior
from miro_gen.corba.naming import CorbaEntry, CorbaNaming, Peer, corba_naming, decide
from miro_gen.corba.server import BeyondLoopback, IIOPServer
from miro_gen.log import logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.service.options import CommonOptions, UsageError
from miro_gen.transport import sockets
from miro_gen.transport.addresses import LOOPBACK, Addresses, server_addresses

if TYPE_CHECKING:
    from miro_gen.corba.notify import EventChannelFactory
    from miro_gen.transport.events.channels import EventChannel
    from miro_gen.transport.events.notify_door import NotifyDoor

_log = logger("MIRO")


class CorbaClient(Protocol):
    """What the IIOP side needs of its `Client` or `Server` (service.server): its common
    options and its ZeroMQ invoker, which the IIOP invoker hands references that are not
    CORBA ones."""

    @property
    def options(self) -> CommonOptions: ...

    @property
    def invoker(self) -> rpc.Invoker: ...


class CorbaNames:
    """The names a server binds in a CORBA naming service (a `NameKeeper`, service.backbone):
    CosNaming has neither leases nor owners, so a bind replaces what was bound, and the names
    live until the server unbinds them when it stops."""

    leased = False

    def __init__(self, naming: CorbaNaming) -> None:
        self.naming = naming
        self._held: dict[str, MiroNaming.Entry] = {}
        self._lock = threading.Lock()

    def bind(self, entry: MiroNaming.Entry) -> bool:
        self.naming.rebind(entry)
        with self._lock:
            self._held[entry.name] = entry
        return True

    def claim(self, entry: MiroNaming.Entry, *, take_over: bool, timeout: float) -> bool:
        return self.bind(entry)  # (no owners to take a name over from)

    def want(self, entry: MiroNaming.Entry, holder: str) -> None:
        self.bind(entry)

    def remove(self, name: str) -> None:
        """Unbind a name bound here from the CORBA naming service."""
        with self._lock:
            if self._held.pop(name, None) is None:
                return
        self.naming.unbind(name)

    def held(self) -> list[MiroNaming.Entry]:
        with self._lock:
            return list(self._held.values())

    def stop(self) -> None:
        """Unbind the names bound here (a naming service that is gone is not waited for)."""
        with self._lock:
            names, self._held = list(self._held), {}
        for name in reversed(names):
            try:
                self.naming.unbind(name)
            except Exception as e:  # the naming service may be gone
                _log.debug("cannot unbind %s: %s", name, e)


class CorbaSide:
    """The IIOP invoker, server and naming of one `Server` or `Client`: `naming` and `names`
    when its naming service is a CORBA one."""

    def __init__(self, client: CorbaClient, naming_url: str | None) -> None:
        self.client = client
        self.iiop = IIOPInvoker(client.invoker, make_server=self._lazy_server)
        self.naming: CorbaNaming | None = None
        self.names: CorbaNames | None = None
        if naming_url is not None:
            self.naming = corba_naming(self.iiop, naming_url, client.options.naming_context)
            self.names = CorbaNames(self.naming)
        self.server: IIOPServer | None = None
        self._factory: EventChannelFactory | None = None  # the Notification doors' factory

    # ---- serving --------------------------------------------------------------------------------

    def serve(self, bind: str, advertise: str) -> IIOPServer:
        """Listen for IIOP: on --iiop-endpoint if given, else on an ephemeral port."""
        host, port = bind, 0
        endpoint = self.client.options.iiop_endpoint
        if endpoint:
            given, _, p = endpoint.rpartition(":")
            port = int(p)
            if given:
                host = advertise = given
        if self.server is None:
            self.server = serve_iiop(self.iiop, self.client.options, host, advertise, port)
            self.iiop.server = self.server
        return self.server

    def _lazy_server(self) -> IIOPServer:
        """A client that passes one of its objects to a CORBA peer serves it (as an ORB does)."""
        a = server_addresses(self.client.options.naming, self.client.options.host)
        return self.serve(a.bind, a.advertise)

    def add(self, servant: rpc.Servant, full: str) -> CorbaRef:
        """Serve `servant` over IIOP under its full name; bind it if the naming is CORBA's."""
        server = self.server or self._lazy_server()
        ref = server.activate(servant, full)
        if self.names is not None:
            self.names.bind(CorbaEntry(full, ref.repo_id, ref.endpoint, ref.key, "", ref))
        return ref

    def open_door(self, channel: EventChannel) -> NotifyDoor:
        """Serve `channel` (hosted here) as a CosNotifyChannelAdmin::EventChannel too, under
        its full name as object key (transport.events.notify_door)."""
        from miro_gen.transport.events.notify_door import NotifyDoor, serve_factory

        server = self.server or self._lazy_server()
        if self._factory is None:
            self._factory = serve_factory(server)
        return NotifyDoor(channel, server, self.iiop, channel.name, self._factory)

    def stub(self, entry: MiroNaming.Entry, cls: type[rpc.StubT]) -> rpc.StubT:
        ref: ObjectRef | None = getattr(entry, "ref", None)
        if ref is None and entry.endpoint.startswith("IOR:"):  # bound through CosNaming
            ref = ref_from_ior(IOR.from_string(entry.endpoint))
        if ref is None:
            ref = ObjectRef(entry.repo_id, entry.endpoint, entry.key)
        return cls(ref, self.iiop)

    def close(self) -> None:
        """Unbind the names bound here (those its server did not unbind when it stopped), stop
        serving (CloseConnection to clients)."""
        if self.names is not None:
            self.names.stop()
        self.iiop.fallback = None
        self.iiop.close()


def serve_iiop(
    invoker: IIOPInvoker, options: CommonOptions, bind: str, advertise: str, port: int = 0
) -> IIOPServer:
    """An IIOP server on `bind`:`port` advertising `advertise`, for a process whose common
    options are `options`: beyond loopback only with --insecure (a UsageError otherwise)."""
    try:
        server = IIOPServer(invoker, bind, port, advertise, beyond_loopback=options.insecure)
    except BeyondLoopback as e:
        where = f"{e.address}:{e.port}" if port else e.address
        raise UsageError(
            f"IIOP on {where} would be open to other machines, in the clear (IIOP has no keys: "
            "the robot's or fleet's key covers ZeroMQ only): serve it on loopback "
            "(--iiop-endpoint 127.0.0.1:PORT), or give --insecure to let anyone who can "
            "connect call this process's objects"
        ) from None
    if sockets.stays_here(bind, binding=True):
        _log.info("serving IIOP at %s", server.endpoint)
    else:
        _log.warning(
            "serving IIOP at %s (bound on %s) in the clear (--insecure): anyone who can "
            "connect may call this process's objects",
            server.endpoint, bind,
        )  # fmt: skip
    return server


def iiop_addresses(options: CommonOptions, towards: str) -> Addresses:
    """Where to serve IIOP for a CORBA peer at `towards` (tcp://HOST:PORT) to call back: on
    loopback when that peer is on this machine, whichever of its addresses it advertises (as
    omniORB does), else as a server's addresses are chosen (`addresses.server_addresses`)."""
    if not options.host and _on_this_machine(sockets.endpoint_host(towards)):
        return Addresses(LOOPBACK, LOOPBACK)
    return server_addresses(towards, options.host)


def _on_this_machine(host: str) -> bool:
    """Whether `host` is (resolves to) an IPv4 address of this machine: one it can bind."""
    try:
        ip = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)[0][4][0]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((ip, 0))
    except (OSError, UnicodeError, IndexError):
        return False
    return True


def _check_naming(opts: CommonOptions, url: str) -> None:
    """A CORBA naming service beyond loopback is talked to in the clear: only with --insecure."""
    host = sockets.endpoint_host(opts.naming)
    if not opts.insecure and not sockets.stays_here(host, binding=False):
        raise UsageError(
            f"the naming service at {url} is a CORBA one on another machine, and IIOP has no "
            "keys or encryption: give --insecure to talk to it (and the objects it names) in "
            "the clear"
        )


def corba_for(client: CorbaClient) -> CorbaSide | None:
    """The CORBA side of a client or server whose options call for one, else None."""
    opts = client.options
    url = opts.naming_url
    corba_naming_url = None
    if url is not None:
        peer = decide(url)
        if peer == Peer.GIOP:
            _check_naming(opts, url)
            corba_naming_url = url
        elif peer == Peer.ZMQ:
            _log.info("%s is a miro naming service (ZeroMQ) at %s", url, opts.naming)
        else:
            _log.notice(
                "nothing answers at %s yet: using it as a miro naming service (ZeroMQ); give "
                "--naming IOR:... for a CORBA one started later", opts.naming,
            )  # fmt: skip
    if corba_naming_url is None and not opts.iiop_endpoint:
        return None
    return CorbaSide(client, corba_naming_url)
