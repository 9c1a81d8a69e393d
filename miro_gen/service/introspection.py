"""The service object: what every Server answers beside its own objects.

Every Server serves a `MiroService::Service` (idl/MiroService.idl) under the object key
`_service` at its endpoint, so that whoever holds a reference to any of its objects can reach
it, and binds it in the naming service as `<context>/_services/<name>` when it starts serving
(`<name>`: $MIRO_SERVICE, which `miro launch` sets, else its program's name). Through it the
live tools, with no generated code of their own, learn the process's objects and their
interface schemas, the events it publishes (with the payloads' data schemas) and subscribes to,
and read, change and dump its parameter objects. See docs/PROTOCOL.md, "The service object".
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import MiroNaming
import MiroService
import MiroService__POA

from miro_gen import log
from miro_gen.exceptions import SystemException
from miro_gen.runtime.rpc import Servant
from miro_gen.service.backbone import CallServer, NameKeeper
from miro_gen.service.options import CommonOptions
from miro_gen.transport.events import offers
from miro_gen.transport.events.channels import EventChannel
from miro_gen.transport.reactor import Reactor

if TYPE_CHECKING:  # loaded when first used: a service that never reads parameters, never
    from lxml import etree  # pays for lxml

    from miro_gen.params.runtime.live import Exposed
    from miro_gen.transport.events.supplier import StructuredPushSupplier

SERVICE_KEY = b"_service"
SERVICES = "_services"  # the naming context, under a process's own, of the service objects
CHANGED_EVENT = "ParametersChanged"
APPLY_TIMEOUT = 5.0  # seconds a change waits for the reactor thread
BIND_TIMEOUT = 2.0  # seconds each naming call of binding the service object may take
STARTED = time.time()
_log = log.logger("MIRO")


def service_name(argv0: str) -> str:
    """The name a process's service object is bound under: $MIRO_SERVICE, else its program's
    (`services/gps` -> gps, `exampleA.py` -> exampleA, `pkg/__main__.py` -> pkg)."""
    given = os.environ.get("MIRO_SERVICE", "").strip().strip("/")
    if given:
        return given.replace("/", "_")
    path = Path(argv0 or "python")
    name = path.parent.name if path.stem == "__main__" else path.stem
    return "-".join((name or "python").split()) or "python"


class ServicePort(Protocol):
    """What the service object needs of its process (service.server.Server gives it): its
    options (the naming context), the objects it serves, the names it keeps, its reactor (on
    which parameters change) and its event channels (where changes are announced)."""

    @property
    def options(self) -> CommonOptions: ...

    @property
    def adapter(self) -> CallServer: ...

    @property
    def names(self) -> NameKeeper: ...

    def bound_entries(self) -> list[MiroNaming.Entry]: ...

    def reactor(self) -> Reactor: ...

    def resolve_channel(self, name: str = ...) -> EventChannel: ...


def servant_class(servant: Servant, repo_id: str) -> type[Any] | None:
    """The generated class in `servant`'s ancestry whose interface is `repo_id`."""
    for cls in type(servant).__mro__:
        if cls.__dict__.get("_repo_id") == repo_id and "_interface_schema" in cls.__dict__:
            return cls
    return None


class ServiceImpl(MiroService__POA.Service):
    """`MiroService::Service` for the process of `server`."""

    def __init__(self, server: ServicePort, name: str) -> None:
        self.server = server
        self.name = name
        self.bound = False  # bind_service has been called
        self.thread: threading.Thread | None = None  # binding it in the background
        self._supplier: StructuredPushSupplier | None = None

    def join(self) -> None:
        """Wait for a bind in the background to end (its naming calls are short)."""
        if self.thread is not None and self.thread is not threading.current_thread():
            self.thread.join(BIND_TIMEOUT * 3 + 1)

    def describe(self) -> MiroService.Description:
        from miro_gen.params.runtime import live

        names = self.server.bound_entries()
        by_key = {e.key: e.name for e in names}
        objects = []
        for key, servant in self.server.adapter.servants():
            if servant is self:
                continue
            objects.append(
                MiroService.ServedObject(
                    by_key.get(key, ""), servant._repo_id, servant._interface_hash, key
                )
            )
        return MiroService.Description(
            name=self.name,
            naming_context=self.server.options.naming_context,
            host=socket.gethostname(),
            pid=os.getpid(),
            program=" ".join(sys.argv),
            started=STARTED,
            objects=objects,
            offers=[MiroService.Offer(*o) for o in offers.offers()],
            subscriptions=[MiroService.Subscription(*s) for s in offers.subscriptions()],
            parameters=[
                MiroService.ParameterSet(e.section, e.category, e.type_name, e.document)
                for e in live.exposed()
            ],
        )

    def interface_schema(self, repo_id: str) -> str:
        for _, servant in self.server.adapter.servants():
            cls = servant_class(servant, repo_id)
            if cls is not None and cls._interface_schema:
                return str(cls._interface_schema)
        raise MiroService.NotFound(what=f"no object here implements {repo_id} with a schema")

    def type_schema(self, type_hash: str) -> str:
        from miro_gen.runtime import registry

        cls = registry.lookup(type_hash)  # the reactor's thread: the types imported here
        if cls is None:
            raise MiroService.NotFound(what=f"no type here has the hash {type_hash}")
        return str(cls._data_schema)

    def get_parameters(self, section: str, category: str) -> str:
        return _text(self._find(section, category).element())

    def set_parameters(self, section: str, category: str, element: str) -> str:
        from miro_gen.params import ParamsError
        from miro_gen.params.runtime import live
        from miro_gen.params.runtime.xmlsafe import XmlError, parse_xml

        target = self._find(section, category)
        try:
            elem = parse_xml(element, live.SOURCE).getroot()
        except XmlError as e:
            raise MiroService.InvalidParameters([str(d) for d in e.diagnostics]) from None
        done = threading.Event()
        failed: list[BaseException] = []

        def apply() -> None:  # on the reactor thread, between two of the service's handlers
            try:
                live.change(target, elem)
            except BaseException as e:  # handed to the caller's thread below
                failed.append(e)
            finally:
                done.set()

        reactor = self.server.reactor()
        if reactor.in_reactor_thread():
            apply()
        else:
            reactor.call_soon(apply)
            if not done.wait(APPLY_TIMEOUT):
                raise MiroService.InvalidParameters(
                    [f"{live.SOURCE}: error: the service did not apply the change in time"]
                )
        if failed:
            if isinstance(failed[0], ParamsError):
                raise MiroService.InvalidParameters([str(d) for d in failed[0].diagnostics])
            raise failed[0]
        text = _text(target.element())
        _log.notice("parameters %s/%s changed", target.section, target.category)
        self._announce(target, text)
        return text

    def dump_parameters(self) -> str:
        from lxml import etree

        from miro_gen.params.runtime import live

        root = live.document()
        etree.indent(root, space="  ")
        body = etree.tostring(root, encoding="unicode")
        return f'<?xml version="1.0" encoding="UTF-8"?>\n{body}'

    def _find(self, section: str, category: str) -> Exposed:
        from miro_gen.params.runtime import live

        try:
            return live.find(section, category)
        except LookupError as e:
            raise MiroService.NotFound(what=str(e)) from None

    def _announce(self, target: Exposed, text: str) -> None:
        """Publish a ParametersChanged event on the EventChannel, when there is one."""
        from miro_gen.transport.events import StructuredPushSupplier

        try:
            if self._supplier is None:
                self._supplier = StructuredPushSupplier(self.server.resolve_channel())
            event = MiroService.ParametersChanged(self.name, target.section, target.category, text)
            self._supplier.push(CHANGED_EVENT, event)
        except Exception as e:  # no channel (not bound, naming unreachable): no event
            _log.debug("no %s event: %s", CHANGED_EVENT, e)


def _text(elem: etree._Element) -> str:
    from lxml import etree

    return str(etree.tostring(elem, encoding="unicode"))


def bind_service(server: ServicePort, impl: ServiceImpl, background: bool = False) -> None:
    """Bind the service object as `<context>/_services/<name>` (once). A name held by another
    live process gets this one's pid appended, unless $MIRO_SERVICE named it (a launch's
    restart: the name is taken over from the run before). A process whose naming service does
    not answer is left unbound. `background`: from a thread of its own, which the server's
    clean-up waits for (`ServiceImpl.join`)."""
    if impl.bound or not server.names.leased:
        return  # (names in a CORBA naming service are CORBA objects': no service object)
    impl.bound = True
    if not background:
        _bind(server, impl)
        return
    with contextlib.suppress(RuntimeError):  # an interpreter on its way out
        impl.thread = threading.Thread(
            target=_bind, args=(server, impl), name="miro-service", daemon=True
        )
        impl.thread.start()


def _bind(server: ServicePort, impl: ServiceImpl) -> None:
    names = server.names
    ref = server.adapter.reference_for(impl)
    full = f"{server.options.naming_context}/{SERVICES}/{impl.name}"
    entry = MiroNaming.Entry(full, ref.repo_id, ref.endpoint, ref.key, impl._interface_hash)
    # $MIRO_SERVICE names one service (a launch's): its earlier run's name is taken over. A
    # program's name may be run twice at once: a second copy binds its own name.
    launched = bool(os.environ.get("MIRO_SERVICE"))
    try:
        try:
            kept = names.claim(entry, take_over=launched, timeout=BIND_TIMEOUT)
        except MiroNaming.AlreadyBound as e:
            if launched:  # another owner's: bound when it is free
                names.want(entry, e.holder)
                return
            entry.name = f"{full}-{os.getpid()}"
            kept = names.claim(entry, take_over=False, timeout=BIND_TIMEOUT)
        if kept:  # (else the server stopped meanwhile: nothing was left behind)
            _log.notice("bound %s in the naming service", entry.name)
    except (SystemException, MiroNaming.InvalidName, MiroNaming.NotFound) as e:
        _log.debug("the service object is not bound: %s", e)
    except MiroNaming.AlreadyBound as e:
        _log.debug("the service object is not bound: %s is held by %s", e.name, e.holder)
