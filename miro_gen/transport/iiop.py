"""What a `Server` or `Client` does differently when it talks to the CORBA world (its IIOP side).

`corba_for(client)` looks at the common options: a naming-service URL that turns out to be a
CORBA naming service (`miro_gen.corba.naming.decide`), or `--iiop-endpoint`. Then the process
gets an IIOP invoker (which hands references that are not CORBA ones to the ZeroMQ invoker),
and a server an IIOP listener: `add_to_name_service` serves the servant over IIOP under its full
name as object key (`robot1/ExampleA`: persistent when the port is fixed, and reachable as
`corbaloc:iiop:HOST:PORT/robot1/ExampleA`) and binds its IOR in the CORBA naming service, or,
with a ZeroMQ naming service and `--iiop-endpoint`, serves it over both.
"""

from __future__ import annotations

import threading
from typing import Any

from miro_gen.corba.client import IIOPInvoker
from miro_gen.corba.ior import CorbaRef
from miro_gen.corba.naming import CorbaEntry, CorbaNaming, Peer, corba_naming, decide
from miro_gen.corba.server import IIOPServer
from miro_gen.log import logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef

_log = logger("MIRO")


class CorbaSide:
    """The IIOP invoker, server and naming of one `Server` or `Client`."""

    def __init__(self, client: Any, naming_url: str | None) -> None:
        self.client = client
        self.iiop = IIOPInvoker(client.invoker, make_server=self._lazy_server)
        self.naming: CorbaNaming | None = None
        if naming_url is not None:
            self.naming = corba_naming(self.iiop, naming_url, client.options.naming_context)
        self.server: IIOPServer | None = None
        self._names: list[str] = []
        self._lock = threading.Lock()

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
            self.server = IIOPServer(self.iiop, host, port, advertise)
            self.iiop.server = self.server
            _log.info("serving IIOP at %s", self.server.endpoint)
        return self.server

    def _lazy_server(self) -> IIOPServer:
        """A client that passes one of its objects to a CORBA peer serves it (as an ORB does)."""
        from miro_gen.transport.addresses import server_addresses

        a = server_addresses(self.client.options.naming, self.client.options.host)
        return self.serve(a.bind, a.advertise)

    def add(self, servant: rpc.Servant, full: str) -> CorbaRef:
        """Serve `servant` over IIOP under its full name; bind it if the naming is CORBA's."""
        server = self.server or self._lazy_server()
        ref = server.activate(servant, full)
        if self.naming is not None:
            self.naming.rebind(CorbaEntry(full, ref.repo_id, ref.endpoint, ref.key, "", ref))
            with self._lock:
                self._names.append(full)
        return ref

    def bind(self, entry: Any) -> None:
        """Bind a naming entry of the process (an event channel) in the CORBA naming service."""
        assert self.naming is not None
        self.naming.rebind(entry)
        with self._lock:
            self._names.append(entry.name)

    def unbind(self, full: str) -> None:
        """Unbind a name bound here from the CORBA naming service."""
        assert self.naming is not None
        with self._lock:
            if full not in self._names:
                return
            self._names.remove(full)
        self.naming.unbind(full)

    def stub(self, entry: Any, cls: type[rpc.StubT]) -> rpc.StubT:
        ref = getattr(entry, "ref", None) or ObjectRef(entry.repo_id, entry.endpoint, entry.key)
        return cls(ref, self.iiop)

    def close(self) -> None:
        """Unbind the names bound here, stop serving (CloseConnection to clients)."""
        with self._lock:
            names, self._names = self._names, []
        for name in reversed(names):
            try:
                assert self.naming is not None
                self.naming.unbind(name)
            except Exception as e:  # the naming service may be gone
                _log.debug("cannot unbind %s: %s", name, e)
        self.iiop.fallback = None
        self.iiop.close()


def corba_for(client: Any) -> CorbaSide | None:
    """The CORBA side of a client or server whose options call for one, else None."""
    opts = client.options
    url = opts.naming_url
    corba_naming_url = None
    if url is not None:
        peer = decide(url)
        if peer == Peer.GIOP:
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
