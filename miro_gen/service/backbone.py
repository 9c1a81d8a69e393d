"""What the service process needs of a backbone: the Protocols `Server` and `Client` hold their
calls and names by (docs/ARCHITECTURE.md, "Where a backbone plugs in").

A backbone carries a process's calls, names and events. The ZeroMQ one is `miro_gen.transport`:
its calls are `transport.rpc` (`ZmqInvoker`, `ObjectAdapter`), its names `transport.naming`
(`NamingClient`, `Leases`), its events `transport.events`. The CORBA world provides calls and
names of its own (`miro_gen.corba`: `IIOPInvoker`, `CorbaNaming`; `service.iiop.CorbaNames`),
which `service.iiop` plugs in at the same seams. The second backbone, Zenoh
(`transport.zenoh`, `--transport zenoh`), provides the same:

* calls: `CallClient`, the invoker generated stubs call through (`runtime.rpc.Invoker`), and
  `CallServer`, the object adapter that serves a process's servants under object keys;
* naming: `Naming`, names looked up and listed, and `NameKeeper`, the names one server keeps
  bound while it runs (owners, leases, names taken over from the server's earlier run);
* events: `PublishingLink` and `SubscribingLink` (transport.events.links), what a supplier
  and a consumer need of their link to a channel, which the channel makes for them
  (`EventChannel.publishing`, `.subscribing`); what channels need of their process is
  `ChannelServer` (transport.events.channels), which `Server` satisfies.

The implementations do not import these Protocols: they satisfy them, and mypy checks each where
`Server` and `Client` hold them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import MiroNaming

from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Invoker, Servant


class CallClient(Invoker, Protocol):
    """The client side of calls: delivers requests to the objects references name (the
    runtime's `Invoker`), and closes its connections."""

    def close(self) -> None: ...


class CallServer(Protocol):
    """The server side of calls: serves a process's servants, each under an object key, at the
    endpoint its references carry."""

    @property
    def endpoint(self) -> str: ...

    def activate(self, servant: Servant, key: bytes | None = None) -> ObjectRef:
        """Serve `servant` under `key` (a new one when None); its reference."""
        ...

    def deactivate(self, key: bytes) -> None: ...

    def servants(self) -> list[tuple[bytes, Servant]]:
        """The servants served, with their keys."""
        ...

    def reference_for(self, servant: Servant) -> ObjectRef:
        """The reference of `servant`, served first if it is not yet."""
        ...

    def drain(self, timeout: float) -> bool:
        """Refuse new calls and wait up to `timeout` seconds for those running to be answered;
        whether they all were."""
        ...

    def close(self) -> None: ...


class Naming(Protocol):
    """Names as a process looks them up, in its naming context (`context`) first: the miro
    naming service's client (`transport.naming.client.NamingClient`) or a CORBA naming
    service's (`corba.naming.CorbaNaming`)."""

    @property
    def context(self) -> str: ...

    def full_name(self, name: str) -> str:
        """`name` as this process binds it: under its context, unless it is a path already."""
        ...

    def resolve(self, name: str) -> MiroNaming.Entry:
        """The entry bound as `name` (MiroNaming.NotFound names what was looked for)."""
        ...

    def entries(self, prefix: str = "") -> Sequence[MiroNaming.Entry]:
        """Every entry whose name starts with `prefix`, in name order."""
        ...


class NameKeeper(Protocol):
    """The names one server keeps bound while it runs, and unbinds when it stops: leases in the
    miro naming service (`transport.naming.leases.Leases`), bindings in a CORBA naming service
    (`service.iiop.CorbaNames`). `leased`: whether a name outlives its server only until its
    lease ends (a name in a CORBA naming service outlives it until unbound)."""

    @property
    def leased(self) -> bool: ...

    def bind(self, entry: MiroNaming.Entry) -> bool:
        """Bind `entry` and keep it, taking it over from an earlier run of this service; False
        when another owner holds it: it is bound when that one lets it go, and said so."""
        ...

    def claim(self, entry: MiroNaming.Entry, *, take_over: bool, timeout: float) -> bool:
        """Bind `entry` once and keep it, from any thread, with calls of `timeout` seconds
        (taking it over from an earlier run of this service only with `take_over`); False when
        the server stopped meanwhile (nothing is left behind); MiroNaming.AlreadyBound when
        another owner holds it (not retried)."""
        ...

    def want(self, entry: MiroNaming.Entry, holder: str) -> None:
        """Bind `entry` as soon as `holder`, which has it, lets it go."""
        ...

    def remove(self, name: str) -> None:
        """Stop keeping `name` and unbind it."""
        ...

    def held(self) -> list[MiroNaming.Entry]:
        """The entries kept bound."""
        ...

    def stop(self) -> None:
        """Unbind every name kept, and keep none any more."""
        ...
