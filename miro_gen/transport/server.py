"""`Server` and `Client`: Miro's entry points, in Python.

    server = Server(sys.argv)                 # takes the common options out of sys.argv
    server.add_to_name_service(ExampleImpl(), "ExampleA")
    server.run()                              # until SIGINT / SIGTERM, then unbinds its names

    client = Client(sys.argv)
    example = client.resolve_name("ExampleA", Miro.Example, wait=10)  # up to 10 s for it
    example.setData(0.0, 10.0)                # follows ExampleA if its server restarts

A Server owns the process's reactor and one ROUTER socket for all its objects, bound and
advertised as `miro_gen.transport.addresses` decides (reachable from the naming service's host,
or `--host`); its names live
under its naming context (`-MNC`, default the host name) with leases that a background thread
renews, re-binding them when the naming service has restarted. A Client only calls out.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import sys
import threading
import time
import uuid
from collections.abc import Callable, MutableSequence, Sequence
from typing import Any, TypeVar

import MiroNaming
import zmq

from miro_gen import lifecycle, log
from miro_gen.exceptions import TRANSIENT, SystemException
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Servant, Stub
from miro_gen.transport import channel_link, sockets
from miro_gen.transport.adapter import ObjectAdapter
from miro_gen.transport.addresses import server_addresses
from miro_gen.transport.channels import EventChannel, resolve_channel
from miro_gen.transport.introspection import SERVICE_KEY, ServiceImpl, bind_service, service_name
from miro_gen.transport.invoker import ZmqInvoker
from miro_gen.transport.naming import DEFAULT_LEASE, NamingClient, naming_errors
from miro_gen.transport.options import CommonOptions, parse_common_options
from miro_gen.transport.reactor import Reactor

StubT = TypeVar("StubT", bound=Stub)
RENEW_TIMEOUT = 2.0  # seconds a lease renewal may take
RETRY_BIND = 0.2  # seconds between attempts to bind a name another owner's lease still holds
WAIT_STEP = 0.5  # at most this many seconds between two looks for a name being waited for
_log = log.logger("MIRO")


def _corba_side(client: Client) -> Any:
    """The CORBA side of a process whose options name a CORBA naming service or an IIOP
    endpoint (miro_gen.transport.iiop), else None; the CORBA code loads only then."""
    o = client.options
    if o.naming_url is None and o.iiop_endpoint is None:
        return None
    from miro_gen.transport.iiop import corba_for

    return corba_for(client)


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

    def __init__(self, argv: Sequence[str] | None = None, *, context: Any = None) -> None:
        self.options, self.argv = _take_options(argv)
        if not self.options.naming_given and os.environ.get("MIRO_DISCOVERY", "1") != "0":
            from miro_gen.transport.discovery import naming_for  # the manual's -m 1

            self.options.naming = naming_for(self.options.naming)
        self.context = context if context is not None else zmq.Context.instance()
        self._configure_sockets(None)
        self.invoker = ZmqInvoker(self.context)
        self.corba = _corba_side(self)  # the CORBA world: a CORBA naming service, IIOP
        self.naming: Any = (
            self.corba.naming
            if self.corba is not None and self.corba.naming is not None
            else NamingClient(self.invoker, self.options.naming, self.options.naming_context)
        )

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
                entry: MiroNaming.Entry = self.naming.resolve(name)
                return entry
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


class Server(Client):
    """Serves objects: a reactor, a ROUTER socket, and names kept alive in the naming service."""

    def __init__(
        self,
        argv: Sequence[str] | None = None,
        *,
        context: Any = None,
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
        self.adapter = ObjectAdapter(
            self._reactor,
            self.invoker,
            bind=f"tcp://{self.addresses.bind}:*",
            host=self.addresses.advertise,
        )
        self.invoker.adapter = self.adapter
        if self.corba is not None:
            self.corba.serve(self.addresses.bind, self.addresses.advertise)
        self.owner = uuid.uuid4().hex
        self.lease = lease
        self._names: dict[str, MiroNaming.Entry] = {}
        self._names_lock = threading.Lock()
        self._stop = threading.Event()
        self._renewer: threading.Thread | None = None
        self._cleaned = False
        self._on_shutdown: list[Callable[[], object]] = []
        self.hosted_channels: dict[str, EventChannel] = {}  # hosted here, by full name
        # The service object (transport/introspection.py): bound when run() starts.
        self.service = ServiceImpl(self, service_name(self.argv[0]))
        self.adapter.activate(self.service, SERVICE_KEY)
        if clock is not None:
            from miro_gen.transport.log_clock import follow_log_clock

            follow_log_clock(self, self.options.clock.partition(":")[2] or "LogClock", clock)

    def reactor(self) -> Reactor:
        return self._reactor

    def add_to_name_service(self, servant: Servant, name: str) -> ObjectRef:
        """Serve `servant` and bind it as `name` under this server's naming context (or at the
        path given); its reference. Replaces an older binding of the name, as Miro does."""
        full = self.naming.full_name(name)
        if self.corba is not None:  # served over IIOP (and bound in a CORBA naming service)
            corba_ref: ObjectRef = self.corba.add(servant, full)
            if self.corba.naming is not None:
                self._unbind_if_interrupted()
                return corba_ref
        ref = self.adapter.reference_for(servant)
        entry = MiroNaming.Entry(full, ref.repo_id, ref.endpoint, ref.key, servant._interface_hash)
        self.bind_entry(entry)
        return ref

    def bind_entry(self, entry: MiroNaming.Entry) -> None:
        """Bind a naming entry under this server's lease (objects, event channels). A name
        that another server holds is waited for, up to a lease (the entry of a server killed
        without unbinding lives that long); AlreadyBound after that."""
        if self.corba is not None and self.corba.naming is not None:
            self.corba.bind(entry)  # CosNaming: no lease; unbound when the server stops
            self._unbind_if_interrupted()
            _log.notice("bound %s in the naming service", entry.name)
            return
        lease_ms = int(self.lease * 1000)
        deadline = time.monotonic() + max(self.lease, DEFAULT_LEASE) + 0.5
        told = False
        while True:
            try:
                with naming_errors(self.options.naming, f"bind {entry.name}"):
                    self.naming.registry.rebind(entry, self.owner, lease_ms)
                break
            except TRANSIENT as e:
                raise self._unreachable(e) from None
            except MiroNaming.AlreadyBound:
                if time.monotonic() >= deadline:
                    raise
                if not told:
                    told = True
                    _log.notice(
                        "%s is bound by another server (one killed without unbinding?): "
                        "waiting for its lease to end",
                        entry.name,
                    )
                time.sleep(RETRY_BIND)
        self.keep_entry(entry)
        _log.notice("bound %s in the naming service", entry.name)
        bind_service(self, self.service)  # with its first name: nothing can come between

    def keep_entry(self, entry: MiroNaming.Entry) -> bool:
        """Keep `entry`, bound already, under this server's lease (renewed, bound again in a
        restarted naming service, unbound at the end); False when the server is stopping."""
        with self._names_lock:
            if self._stop.is_set():
                return False
            self._names[entry.name] = entry
        self._start_renewing()
        return True

    def bound_entries(self) -> list[MiroNaming.Entry]:
        """The naming entries this server keeps bound."""
        with self._names_lock:
            return list(self._names.values())

    def remove_from_name_service(self, name: str) -> None:
        """Unbind `name`, bound by this server, and stop renewing it. Its object is still
        served until deactivated (`adapter.deactivate`); another server may bind the name now
        instead of waiting for this one's lease."""
        full = self.naming.full_name(name)
        if self.corba is not None and self.corba.naming is not None:
            self.corba.unbind(full)
            return
        with self._names_lock:
            self._names.pop(full, None)
        with (
            contextlib.suppress(MiroNaming.NotFound),
            naming_errors(self.options.naming, f"unbind {full}"),
        ):
            self.naming.registry.unbind(full, self.owner)

    def _unbind_if_interrupted(self) -> None:
        """A server whose names live in a CORBA naming service (no leases there) unbinds them
        when interrupted before it runs, as `_start_renewing` arranges for leased names."""
        lifecycle.forget(self._cleanup)
        lifecycle.at_interrupt(self._cleanup)

    def resolve_channel(self, name: str = "EventChannel") -> EventChannel:
        """The event channel bound as `name` (see EventChannelFactory.create_channel)."""
        return resolve_channel(self, name)

    def on_shutdown(self, fn: Callable[[], object]) -> None:
        """Call `fn()` when `run()` ends, before the sockets close (newest first)."""
        self._on_shutdown.append(fn)

    def run(self) -> None:
        """Serve until SIGINT, SIGTERM or `shutdown()`; then unbind this server's names. A
        signal that came before (see `miro_gen.lifecycle`) ends it at once; one that comes
        during the clean-up does not interrupt it."""
        with lifecycle.signals_stop(self.shutdown) as signals:
            try:
                if not signals.pending:
                    bind_service(self, self.service, background=True)  # a consumer's
                    self._reactor.run()
            finally:
                signals.cleaning_up()
                self._cleanup()

    def shutdown(self) -> None:
        """Make `run()` return (from any thread)."""
        self._reactor.stop()

    def _cleanup(self) -> None:
        if self._cleaned:
            return
        self._cleaned = True
        lifecycle.forget(self._cleanup)
        self._stop.set()
        self.service.join()  # a bind of the service object still under way
        if self._renewer is not None:  # its socket must be closed by no one else while in use
            self._renewer.join(RENEW_TIMEOUT + 1)
        with self._names_lock:
            names, self._names = list(self._names), {}
        for name in names:
            with contextlib.suppress(SystemException, MiroNaming.NotFound):
                self.naming.registry.unbind(name, self.owner)
        for fn in reversed(self._on_shutdown):
            try:
                fn()
            except Exception:
                _log.exception("a shutdown handler failed")
        channel_link.close_watcher(self._reactor)  # its look-up uses our invoker
        self.adapter.close()
        self._reactor.close()
        self.close()

    # ---- leases --------------------------------------------------------------------------------

    def _start_renewing(self) -> None:
        if self._renewer is None:
            lifecycle.at_interrupt(self._cleanup)  # unbind if interrupted before run()
            self._registry_for_renewal = self.naming.registry_stub(self.invoker, RENEW_TIMEOUT)
            self._renewer = threading.Thread(
                target=self._renew_loop, name="miro-lease", daemon=True
            )
            self._renewer.start()

    def _renew_loop(self) -> None:
        held_elsewhere: set[str] = set()  # lost names another server holds now (said once)
        while not self._stop.wait(self.lease / 3):
            lease_ms = int(self.lease * 1000)
            with self._names_lock:
                entries = dict(self._names)
            try:
                # The naming service says, name by name, which it does not hold for us (it
                # restarted, a lease ran out while we were cut off): those are bound again.
                lost = self._registry_for_renewal.renew(self.owner, list(entries), lease_ms)
                for name in lost:
                    with self._names_lock:  # (not one removed meanwhile)
                        entry = self._names.get(name)
                    if entry is None:
                        continue
                    try:
                        self._registry_for_renewal.rebind(entry, self.owner, lease_ms)
                    except MiroNaming.AlreadyBound:
                        if name not in held_elsewhere:
                            held_elsewhere.add(name)
                            _log.warning(
                                "%s is bound by another server now; it is bound again here "
                                "when that one's lease ends",
                                name,
                            )
                        continue
                    held_elsewhere.discard(name)
                    _log.notice("bound %s again in the naming service", name)
            except SystemException as e:
                _log.warning("cannot renew names: %s", e)
