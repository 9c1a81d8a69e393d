"""`Server` and `Client`: Miro's entry points, in Python.

    server = Server(sys.argv)                 # takes the common options out of sys.argv
    server.add_to_name_service(ExampleImpl(), "ExampleA")
    server.run()                              # until SIGINT / SIGTERM, then unbinds its names

    client = Client(sys.argv)
    example = client.resolve_name("ExampleA", Miro.Example, wait=10)  # up to 10 s for it
    example.setData(0.0, 10.0)                # follows ExampleA if its server restarts

A Server owns the process's reactor and one ROUTER socket for all its objects, bound and
advertised as `miro_gen.transport.addresses` decides (reachable from the naming service's host,
or `--host`); its names live under its naming context (`-MNC`, default the host name) with
leases that a background thread renews (`transport.naming.leases`): taken over at start from an
earlier run of the same service, and never given up when another owner holds them. A Client
only calls out.

Both hold the backbone they run over by the Protocols of `service.backbone`: the calls
(`invoker`, a server's `adapter`), the naming (`naming`) and a server's names (`names`); the
ZeroMQ ones are made here, a CORBA naming service's come from the IIOP side (`service.iiop`).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Callable, MutableSequence, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import MiroNaming
import zmq

from miro_gen import lifecycle, log
from miro_gen.exceptions import TRANSIENT
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Servant, Stub
from miro_gen.service.backbone import CallClient, CallServer, NameKeeper, Naming
from miro_gen.service.introspection import SERVICE_KEY, ServiceImpl, bind_service, service_name
from miro_gen.service.options import CommonOptions, UsageError, parse_common_options
from miro_gen.transport import sockets
from miro_gen.transport.addresses import server_addresses
from miro_gen.transport.events import channel_link
from miro_gen.transport.events.channels import EventChannel, resolve_channel
from miro_gen.transport.naming.client import DEFAULT_LEASE, NamingClient
from miro_gen.transport.naming.leases import Leases
from miro_gen.transport.reactor import Reactor
from miro_gen.transport.rpc.adapter import ObjectAdapter
from miro_gen.transport.rpc.invoker import ZmqInvoker

if TYPE_CHECKING:  # loaded when the options call for it
    from miro_gen.service.iiop import CorbaSide
    from miro_gen.transport.events.channels import ChannelLinks
    from miro_gen.transport.tlsfiles import TlsFiles
    from miro_gen.transport.zenoh.invoker import ZenohInvoker

StubT = TypeVar("StubT", bound=Stub)
WAIT_STEP = 0.5  # at most this many seconds between two looks for a name being waited for
DRAIN_TIMEOUT = 2.0  # seconds the calls being served may take to finish when a server stops
_log = log.logger("MIRO")


def _corba_side(client: Client) -> CorbaSide | None:
    """The CORBA side of a process whose options name a CORBA naming service or an IIOP
    endpoint (miro_gen.service.iiop), else None; the CORBA code loads only then."""
    o = client.options
    if o.naming_url is None and o.iiop_endpoint is None:
        return None
    from miro_gen.service.iiop import corba_for

    return corba_for(client)


def _calls_to_corba(client: Client) -> CorbaSide:
    """An IIOP side for a process that found a CORBA object in its ZeroMQ naming service."""
    from miro_gen.service.iiop import CorbaSide

    return CorbaSide(client, None)


def _take_options(argv: Sequence[str] | None) -> tuple[CommonOptions, list[str]]:
    """Parse the common options of `argv` (sys.argv by default; [0] is the program) and, when
    it is a mutable list, remove them from it as Miro does."""
    args = sys.argv if argv is None else argv
    opts, rest = parse_common_options(list(args[1:]))
    if isinstance(args, MutableSequence):
        args[1:] = rest
    for ignored in opts.ignored:
        print(f"note: {ignored} is a TAO option; miro-gen ignores it", file=sys.stderr)
    log.configure(opts.log_level, opts.log_filter)
    return opts, [args[0] if args else "", *rest]


class Client:
    """Calls remote objects found through the naming service."""

    def __init__(
        self, argv: Sequence[str] | None = None, *, context: zmq.Context[Any] | None = None
    ) -> None:
        self.options, self.argv = _take_options(argv)
        self.zenoh: Any = None  # the Zenoh session (--transport zenoh, transport.zenoh)
        zenoh = self.options.transport == "zenoh"
        if not self.options.naming_given and os.environ.get("MIRO_DISCOVERY", "1") != "0":
            from miro_gen.transport.naming.discovery import naming_for  # the manual's -m 1

            # (on Zenoh: the announced router of `miro naming --zenoh`)
            self.options.naming = naming_for(self.options.naming, "zenoh" if zenoh else "zmq")
        self.context = context if context is not None else zmq.Context.instance()
        self._configure_sockets(None)
        # (a Server's adapter serves the local objects passed as arguments)
        self._zmq_invoker: ZmqInvoker | ZenohInvoker
        naming_endpoint = self.options.naming
        owner_endpoint = None  # where this process binds names (the naming client's default)
        if zenoh:  # calls over queryables, names in the registry beside the router
            try:
                from miro_gen.transport.zenoh import keys, session
                from miro_gen.transport.zenoh.invoker import ZenohInvoker
            except ImportError as e:
                raise UsageError(
                    f"--transport zenoh needs the Zenoh wheel ({e}): pip install 'miro-gen[zenoh]'"
                ) from None

            self.zenoh = session.open_client(
                self.options.naming, self._router_wait(), self._zenoh_tls()
            )
            self._zmq_invoker = ZenohInvoker(self.zenoh)
            naming_endpoint = keys.NAMING_ENDPOINT
            owner_endpoint = keys.naming_endpoint(keys.owner_part(session.identity(self.zenoh)))
        else:
            self._zmq_invoker = ZmqInvoker(self.context)
        self.invoker: CallClient = self._zmq_invoker
        self.corba = _corba_side(self)  # the CORBA world: a CORBA naming service, IIOP
        self.naming: Naming = (
            self.corba.naming
            if self.corba is not None and self.corba.naming is not None
            else NamingClient(
                self.invoker, naming_endpoint, self.options.naming_context, owner_endpoint
            )
        )

    def _router_wait(self) -> float | None:
        """Seconds to wait for the Zenoh router to be up (a client's: a moment)."""
        return 2.0

    def _zenoh_tls(self) -> TlsFiles | None:
        """The TLS files of this process's Zenoh session (None: plain TCP), from its options
        and where the router is (transport.zenoh.security): ZeroMQ's rules, Zenoh's TLS."""
        from miro_gen.transport.zenoh.security import tls_for

        o = self.options
        return tls_for(keys=o.keys, insecure=o.insecure, talks_to=sockets.endpoint_host(o.naming))

    def resolve_name(
        self, name: str, stub: type[StubT], *, wait: float = 0.0, rebind: bool = True
    ) -> StubT:
        """A stub of the object bound to `name` (in this process's naming context first, then
        at the root; a path such as `robot1/ExampleA` as it is).

        `wait`: seconds to wait for the name to be bound (and the naming service to answer),
        as ROS 2's wait_for_service; then MiroNaming.NotFound (or TRANSIENT). `rebind`: the
        stub looks the name up again when its server has moved (`Stub._set_rebind`)."""
        try:
            entry = self._resolve(name, wait)
        except TRANSIENT as e:
            raise self._unreachable(e) from None
        if entry.repo_id != stub._repo_id:
            _log.debug("%s is a %s, used as a %s", entry.name, entry.repo_id, stub._repo_id)
        elif entry.type_hash and stub._interface_hash and entry.type_hash != stub._interface_hash:
            _log.warning(
                "%s implements another version of %s than this program knows (interface hash "
                "%s, here %s): calls may fail with BAD_OPERATION or MARSHAL",
                entry.name,
                entry.repo_id,
                entry.type_hash[:12],
                stub._interface_hash[:12],
            )
        if self.corba is None and entry.endpoint.startswith(("IOR:", "iiop://")):
            self.corba = _calls_to_corba(self)  # a C++ object named in miro naming (CosNaming)
        if self.corba is not None:  # a CORBA object, or any reached through the IIOP invoker
            found: StubT = self.corba.stub(entry, stub)
        else:
            found = stub(ObjectRef(entry.repo_id, entry.endpoint, entry.key), self.invoker)
        if rebind:
            found._set_rebind(lambda: self._lookup_again(name))
        return found

    def _resolve(self, name: str, wait: float) -> MiroNaming.Entry:
        deadline = time.monotonic() + max(0.0, wait)
        step = 0.05
        said = False
        while True:
            try:
                return self.naming.resolve(name)
            except (MiroNaming.NotFound, TRANSIENT) as e:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise
                if not said:
                    why = e.message if isinstance(e, TRANSIENT) else f"{e.name} is not bound yet"
                    _log.notice("waiting for %s: %s", name, why)
                    said = True
                time.sleep(min(step, left))
                step = min(step * 2, WAIT_STEP)

    def _lookup_again(self, name: str) -> ObjectRef:
        entry = self.naming.resolve(name)
        # A CORBA naming service's entries carry the reference as it came (its whole IOR).
        ref: ObjectRef = getattr(entry, "ref", None) or ObjectRef(
            entry.repo_id, entry.endpoint, entry.key
        )
        _log.debug("%s looked up again: %s", entry.name, entry.endpoint)
        return ref

    def _configure_sockets(self, binds: str | None) -> None:
        """The limits and security of this process's sockets (transport.sockets), from its
        options, what it binds on and where its naming service is."""
        o = self.options
        if o.transport == "zenoh":  # ZeroMQ carries nothing beyond this process: plain
            plain = sockets.policy_for(
                keys=None, insecure=False, max_message_size=o.max_message_size
            )
            sockets.configure(self.context, plain)
            return
        policy = sockets.policy_for(
            keys=o.keys,
            insecure=o.insecure,
            max_message_size=o.max_message_size,
            binds=binds,
            talks_to=sockets.endpoint_host(o.naming),
        )
        sockets.configure(self.context, policy)

    def _unreachable(self, error: TRANSIENT) -> TRANSIENT:
        """The naming service did not answer: say so clearly when it is a CORBA one."""
        if self.corba is not None:
            return error
        from miro_gen.corba.naming import explain_unreachable

        return explain_unreachable(self.options.naming, error)

    def close(self) -> None:
        if self.corba is not None:
            self.corba.close()
        self.invoker.close()
        if self.zenoh is not None:
            self.zenoh.close()


class Server(Client):
    """Serves objects: a reactor, a ROUTER socket, and names kept alive in the naming service."""

    def __init__(
        self,
        argv: Sequence[str] | None = None,
        *,
        context: zmq.Context[Any] | None = None,
        bind_host: str | None = None,
        lease: float = DEFAULT_LEASE,
    ) -> None:
        super().__init__(argv, context=context)
        # Before any socket exists: a --host that is not ours is a UsageError, nothing to close.
        self.addresses = server_addresses(self.options.naming, self.options.host, self.options.bind)
        if bind_host is not None:
            self.addresses = dataclasses.replace(self.addresses, bind=bind_host)
        self._configure_sockets(self.addresses.bind)
        clock = None
        if self.options.clock != "wall":  # --clock log: timers and now() follow a log player
            from miro_gen.clock import LogClock, use

            clock = LogClock()
            use(clock)
        self._reactor = Reactor(self.context, clock)
        self.channel_links: ChannelLinks | None = None  # (ZeroMQ's channels have hosts)
        if self.zenoh is not None:
            from miro_gen.transport.zenoh.adapter import ZenohAdapter
            from miro_gen.transport.zenoh.links import ZenohChannels

            self.adapter: CallServer = ZenohAdapter(self.zenoh, self.invoker)
            self.channel_links = ZenohChannels(self.zenoh, self._reactor)
        else:
            self.adapter = ObjectAdapter(
                self._reactor,
                self.invoker,
                bind=f"tcp://{self.addresses.bind}:*",
                host=self.addresses.advertise,
            )
        self._zmq_invoker.adapter = self.adapter
        if self.corba is not None:
            self.corba.serve(self.addresses.bind, self.addresses.advertise)
        self.lease = lease
        # The owner of its names: this service (the same across its restarts, by `miro launch`
        # or by hand) and this run of it (128 random bits in hex, as uuid4().hex was, without
        # uuid's import of platform at start); the naming service adds who it checks we are.
        service = f"{self.options.naming_context}/{service_name(self.argv[0])}"
        self.owner = MiroNaming.Owner(service, os.urandom(16).hex())
        self.names: NameKeeper
        if self.corba is not None and self.corba.names is not None:
            self.names = self.corba.names  # bindings in a CORBA naming service: no leases
        else:
            assert isinstance(self.naming, NamingClient)
            leases = Leases(
                self.naming,
                self.invoker,
                self.owner,
                lease,
                self.options.wait_naming,
                self._unreachable,
            )
            self.naming.before_first_call = leases.wait_for_naming
            self.names = leases
            if self.zenoh is not None:  # and a liveliness token per name
                from miro_gen.transport.zenoh.names import TokenedNames

                self.names = TokenedNames(leases, self.zenoh)
        self.drain_timeout = DRAIN_TIMEOUT
        self._armed = False
        self._cleaned = False
        self._stop_asked = False  # shutdown() was called: run() returns, even if not running yet
        self._on_shutdown: list[Callable[[], object]] = []
        self.hosted_channels: dict[str, EventChannel] = {}  # hosted here, by full name
        # The service object (service/introspection.py): bound when run() starts.
        self.service = ServiceImpl(self, service_name(self.argv[0]))
        self.adapter.activate(self.service, SERVICE_KEY)
        if clock is not None:
            from miro_gen.service.log_clock import follow_log_clock

            follow_log_clock(self, self.options.clock.partition(":")[2] or "LogClock", clock)

    def _router_wait(self) -> float | None:
        return self.options.wait_naming  # as for the naming service (None: until it is up)

    def reactor(self) -> Reactor:
        return self._reactor

    def add_to_name_service(self, servant: Servant, name: str) -> ObjectRef:
        """Serve `servant` and bind it as `name` under this server's naming context (or at the
        path given); its reference. Replaces an older binding of the name, as Miro does."""
        full = self.naming.full_name(name)
        if self.corba is not None:  # served over IIOP (and bound in a CORBA naming service)
            corba_ref: ObjectRef = self.corba.add(servant, full)
            if self.corba.names is not None:
                self._arm_cleanup()
                return corba_ref
        ref = self.adapter.reference_for(servant)
        entry = MiroNaming.Entry(full, ref.repo_id, ref.endpoint, ref.key, servant._interface_hash)
        self.bind_entry(entry)
        return ref

    def bind_entry(self, entry: MiroNaming.Entry) -> None:
        """Bind a naming entry under this server's lease (objects, event channels), taking it
        over from an earlier run of this service. A name that another owner holds is not
        given up on: said loudly, and bound when it is free (`transport.naming.leases`). A
        naming service that does not answer yet is waited for (`--wait-naming`). In a CORBA
        naming service: no lease, unbound when the server stops."""
        self._arm_cleanup()
        if self.names.bind(entry):
            _log.notice("bound %s in the naming service", entry.name)
        bind_service(self, self.service)  # with its first name: nothing can come between

    def bound_entries(self) -> list[MiroNaming.Entry]:
        """The naming entries this server keeps bound."""
        return self.names.held()

    def remove_from_name_service(self, name: str) -> None:
        """Unbind `name`, bound by this server, and stop renewing it. Its object is still
        served until deactivated (`adapter.deactivate`); another server may bind the name now
        instead of waiting for this one's lease."""
        self.names.remove(self.naming.full_name(name))

    def _arm_cleanup(self) -> None:
        """Unbind this server's names if it is interrupted before it runs."""
        if not self._armed:
            self._armed = True
            lifecycle.at_interrupt(self._cleanup)

    def resolve_channel(self, name: str = "EventChannel") -> EventChannel:
        """The event channel bound as `name` (see EventChannelFactory.create_channel)."""
        return resolve_channel(self, name)

    def on_shutdown(self, fn: Callable[[], object]) -> None:
        """Call `fn()` when `run()` ends, before the sockets close (newest first)."""
        self._on_shutdown.append(fn)

    def run(self) -> None:
        """Serve until SIGINT, SIGTERM or `shutdown()`; then unbind this server's names and
        let the calls it is running finish and be answered (at most `drain_timeout` seconds:
        2). A signal that came before (see `miro_gen.lifecycle`) ends it at once; one that
        comes during the clean-up does not interrupt it."""
        with lifecycle.signals_stop(self.shutdown) as signals:
            try:
                if not signals.pending:
                    bind_service(self, self.service, background=True)  # a consumer's
                    # The reactor's run() forgets a stop() that came before it: a signal (or
                    # a shutdown()) from here to its first turn is looked at in that turn.
                    self._reactor.call_soon(self._stop_if_asked)
                    self._reactor.run()
            finally:
                signals.cleaning_up()
                self._cleanup()

    def shutdown(self) -> None:
        """Make `run()` return (from any thread), also when it has not started serving yet."""
        self._stop_asked = True
        self._reactor.stop()

    def _stop_if_asked(self) -> None:
        if self._stop_asked:
            self._reactor.stop()

    def _cleanup(self) -> None:
        if self._cleaned:
            return
        self._cleaned = True
        lifecycle.forget(self._cleanup)
        self.service.join()  # a bind of the service object still under way
        self.names.stop()
        # Its names gone, the calls it is running finish and are answered (bounded); others
        # are refused, completed NO, so that their callers may go elsewhere.
        if not self.adapter.drain(self.drain_timeout):
            _log.warning(
                "calls still running %g s after the server was told to stop: abandoned",
                self.drain_timeout,
            )
        for fn in reversed(self._on_shutdown):
            try:
                fn()
            except Exception:
                _log.exception("a shutdown handler failed")
        channel_link.close_watcher(self._reactor)  # its look-up uses our invoker
        self.adapter.close()
        self._reactor.close()
        self.close()
