"""The naming service as its clients see it: names (paths such as `robot1/ExampleA`) bound to
object references, looked up, listed page by page, and bound by owners.

The service is a remote object, `MiroNaming::Registry` 2.0 (idl/MiroNaming.idl), served under
the key `NameService` at a well-known endpoint (`tcp://127.0.0.1:2809` by default); its side is
`transport.naming.service`. Entries are held under leases that their servers renew. An entry
belongs to an owner that the service checks itself: the caller's principal (its user, or its
host and key, `transport.rpc.caller`) and the service the caller says it is. A process on the
naming service's machine makes its owner's calls over the service's Unix socket
(`transport.local.local_naming_socket`), where the kernel tells the service who calls.
Everything the service holds is bounded: quotas per principal, a table size, entry sizes
(docs/SECURITY.md).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

import MiroNaming

from miro_gen.exceptions import BAD_OPERATION, COMM_FAILURE, TIMEOUT, TRANSIENT, actionable
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Invoker
from miro_gen.transport.local import local_naming_socket
from miro_gen.transport.naming.table import MAX_LEASE_MS, MAX_NAME_BYTES, check_name
from miro_gen.transport.rpc.invoker import REFUSED_MINOR

NAMING_KEY = b"NameService"
DEFAULT_LEASE = 3.0  # seconds an entry lives without renewal
DEFAULT_QUOTA = 2000  # names per principal (a user of the machine, a host), live or kept
DEFAULT_MAX_NAMES = 20_000  # names in all
DEFAULT_HOLD = 3600.0  # seconds a stopped server's names are kept for its principal
MAX_PAGE = 500  # entries in one page of a listing
NAMING_HINT = "is `miro naming` running? see --naming / MIRO_NAMING"
Entry = MiroNaming.Entry

__all__ = [
    "DEFAULT_LEASE",
    "MAX_LEASE_MS",
    "MAX_NAME_BYTES",
    "NAMING_HINT",
    "NAMING_KEY",
    "NamingClient",
    "check_name",
    "list_entries",
    "naming_errors",
]

# The naming errors a program lets through are the user's to fix: one line each (lifecycle).
actionable(
    MiroNaming.NotFound,
    lambda e: (
        f"{e.name} is not bound in the naming service: is its server running? "
        "(`miro nslist` lists what is)"
    ),
)
actionable(MiroNaming.InvalidName, lambda e: f"InvalidName: {e.name}")
actionable(MiroNaming.AlreadyBound, lambda e: f"AlreadyBound: {e.name}")


class NamingClient:
    """Binds and resolves names for a process whose naming context is `context` (a `Naming`,
    service.backbone); `owner_endpoint`: where it binds, when its backbone says (the Zenoh
    registry's key of this process's certificate)."""

    def __init__(
        self, invoker: Invoker, endpoint: str, context: str, owner_endpoint: str | None = None
    ) -> None:
        self.context = context
        self.endpoint = endpoint
        self.ref = ObjectRef(MiroNaming.Registry._repo_id, endpoint, NAMING_KEY)
        # Where this process binds: where its backbone says (`owner_fixed`: only there), else
        # the Unix socket of a naming service on this machine (where it can tell who calls;
        # over TCP when that socket does not answer, transport.naming.leases), else the
        # endpoint itself.
        self.owner_endpoint = owner_endpoint or local_naming_socket(endpoint) or endpoint
        self.owner_fixed = owner_endpoint is not None
        self.registry = self.registry_stub(invoker, 5.0)
        # Called before a look-up until one has been made: a server waits there for a naming
        # service that does not answer yet (transport.naming.leases).
        self.before_first_call: Callable[[], None] | None = None

    def registry_stub(
        self, invoker: Invoker, timeout: float, *, owner: bool = False
    ) -> MiroNaming.Registry:
        """A stub of the naming service with its own call timeout (a lease renewer's); `owner`:
        for the calls that bind, renew and unbind."""
        ref = self.ref
        if owner and self.owner_endpoint != self.endpoint:
            ref = ObjectRef(ref.repo_id, self.owner_endpoint, NAMING_KEY)
        return MiroNaming.Registry(ref, invoker, timeout=timeout)

    def full_name(self, name: str) -> str:
        """A name as bound by this process: under its context unless it is a path already."""
        return name if "/" in name else f"{self.context}/{name}"

    def resolve(self, name: str) -> MiroNaming.Entry:
        """The entry of `name`: a path as it is; a plain name in this process's context first,
        then at the root. NotFound names what was looked for."""
        self._first_call()
        with naming_errors(self.endpoint, f"resolve {name}"):
            return self._resolve(name)

    def _resolve(self, name: str) -> MiroNaming.Entry:
        if "/" in name:
            return self.registry.resolve(name)
        try:
            return self.registry.resolve(f"{self.context}/{name}")
        except MiroNaming.NotFound:
            try:
                return self.registry.resolve(name)
            except MiroNaming.NotFound:
                raise MiroNaming.NotFound(name=f"{self.context}/{name}") from None

    def entries(self, prefix: str = "") -> list[MiroNaming.Entry]:
        """The entries whose names start with `prefix`, in name order, page by page."""
        self._first_call()
        with naming_errors(self.endpoint, "list names"):
            return list_entries(self.registry, prefix)

    def _first_call(self) -> None:
        if self.before_first_call is not None:
            self.before_first_call()
            self.before_first_call = None


def list_entries(registry: MiroNaming.Registry, prefix: str = "") -> list[MiroNaming.Entry]:
    """Every entry whose name starts with `prefix`, asked for a page at a time (as CosNaming's
    BindingIterator gives them), so that no table is too large to list."""
    out: list[MiroNaming.Entry] = []
    after = ""
    while True:
        page = registry.list_page(prefix, after, MAX_PAGE)
        out.extend(page.entries)
        if not page.more or not page.entries:
            return out
        after = page.entries[-1].name


@contextlib.contextmanager
def naming_errors(endpoint: str, what: str) -> Iterator[None]:
    """Failures to reach the naming service, said as such, with what to do about them."""
    try:
        yield
    except (TRANSIENT, COMM_FAILURE, TIMEOUT) as e:
        if NAMING_HINT in e.message or e.message.startswith(f"cannot {what}: "):
            raise  # said already, by an inner naming_errors
        if e.minor == REFUSED_MINOR:  # it runs, but will not have us: say why
            raise TRANSIENT(f"cannot {what}: {e.message}", e.minor, e.completed) from None
        reason = e.message.rsplit(": ", 1)[-1] if ": " in e.message else e.message
        raise TRANSIENT(
            f"cannot {what}: the naming service at {endpoint} cannot be reached ({reason}): "
            f"{NAMING_HINT}",
            e.minor,
            e.completed,
        ) from None
    except BAD_OPERATION as e:
        if "MiroNaming/Registry:" not in e.message:
            raise
        raise BAD_OPERATION(
            f"cannot {what}: the naming service at {endpoint} speaks another version of "
            f"its protocol ({e.message}; this process speaks {MiroNaming.Registry._repo_id}): "
            "run the same miro-gen everywhere",
            e.minor,
            e.completed,
        ) from None
