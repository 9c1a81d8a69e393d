"""A CosNaming service (NamingContext, NamingContextExt, BindingIterator) over a naming table
of paths, so that one naming service answers the CORBA world and miro-gen's alike
(`miro naming --iiop-endpoint`; transport.naming.cosnaming_door gives it the naming service's
table).

Names are paths: the CosNaming name `[{id: robot1}, {id: Gps}]` is the path `robot1/Gps`, a
component with a kind is `id.kind` (the stringified form of the Interoperable Naming Service,
`\\` escaping `/` and `.`). A context is a path: the root (""), one made with
`bind_new_context` (kept by this servant, not in the table), or one that names below it imply.
Each context's object is served on demand under the key `NameService#ctx/PATH` (a servant
locator), so a context's reference outlives the servant that made it, as with a persistent POA.

Who may bind, rebind or unbind a name is the table's to decide (`NameTable`): the caller's
principal, which it works out from the connection. Contexts are not owned: like the path
prefixes of miro-gen's names, anyone may make one. Not offered: `new_context` (a context
exists at a path here) and binding foreign contexts (`bind_context`, `rebind_context`:
federated naming), which raise NO_IMPLEMENT. What a client can make is bounded: contexts,
iterators, the bindings a listing returns.
"""

from __future__ import annotations

import itertools
import threading
from collections import OrderedDict
from typing import ClassVar, NamedTuple, Protocol
from urllib.parse import quote

import MiroNaming

from miro_gen.corba.bodies import CORBA_SYSTEM_EXCEPTIONS
from miro_gen.corba.ior import IOR, UrlError, name_to_string, parse_name, ref_from_ior
from miro_gen.corba.naming import NAMING_CONTEXT, NAMING_CONTEXT_EXT, entry_reference
from miro_gen.corba.servants import GiopUserException, HandServant
from miro_gen.corba.server import IIOPServer
from miro_gen.exceptions import BAD_PARAM, NO_IMPLEMENT, NO_PERMISSION, NO_RESOURCES
from miro_gen.runtime import rpc
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

ROOT_KEY = b"NameService"
CONTEXT_KEY = b"NameService#ctx/"
ITERATOR_KEY = b"NameService#it/"
BINDING_ITERATOR = "IDL:omg.org/CosNaming/BindingIterator:1.0"
MAX_CONTEXTS = 10_000  # contexts made with bind_new_context
MAX_ITERATORS = 100  # binding iterators alive; the oldest goes
MAX_LISTED = 100_000  # bindings a listing gathers
PAGE = 1000  # names asked of the table at a time
_NC = "IDL:omg.org/CosNaming/NamingContext/"
_URL_SAFE = "/.\\;-_~!$&()*+,=:@"  # what a corbaname URL keeps of a stringified name

Name = list[tuple[str, str]]


class NameTable(Protocol):
    """The names a CosNaming service answers for (transport.naming.cosnaming_door: miro
    naming's)."""

    def resolve(self, path: str) -> MiroNaming.Entry | None:
        """The entry bound at `path`, if any."""
        ...

    def bind(self, entry: MiroNaming.Entry, replace: bool) -> None:
        """Bind `entry` for the caller (replacing one of the caller's if `replace`):
        MiroNaming.AlreadyBound when it may not, NO_PERMISSION, NO_RESOURCES, BAD_PARAM."""
        ...

    def unbind(self, path: str) -> bool:
        """Unbind the caller's entry at `path`; False when there is none (NO_PERMISSION when
        it is another's)."""
        ...

    def names(self, prefix: str, after: str, how_many: int) -> tuple[list[str], bool]:
        """Bound paths starting with `prefix`, after `after`, in order; whether more follow."""
        ...


# ---- exceptions -------------------------------------------------------------------------------


class NotFound(GiopUserException):
    _repo_id = _NC + "NotFound:1.0"
    MISSING_NODE, NOT_CONTEXT, NOT_OBJECT = 0, 1, 2

    def __init__(self, why: int, rest: Name) -> None:
        super().__init__(why)
        self.why = why
        self.rest = rest

    def write_members(self, out: CdrOutput) -> None:
        out.ulong(self.why)
        _put_name(out, self.rest)


class InvalidName(GiopUserException):
    _repo_id = _NC + "InvalidName:1.0"


class AlreadyBound(GiopUserException):
    _repo_id = _NC + "AlreadyBound:1.0"


class NotEmpty(GiopUserException):
    _repo_id = _NC + "NotEmpty:1.0"


class InvalidAddress(GiopUserException):
    _repo_id = "IDL:omg.org/CosNaming/NamingContextExt/InvalidAddress:1.0"


# ---- names ----------------------------------------------------------------------------------


def _put_name(out: CdrOutput, name: Name) -> None:
    out.ulong(len(name))
    for ident, kind in name:
        out.string(ident)
        out.string(kind)


def _get_name(inp: CdrInput) -> Name:
    n = inp.length(8, "name")
    if n == 0 or n > 64:
        raise InvalidName()
    name = [(inp.string("name id"), inp.string("name kind")) for _ in range(n)]
    if any(not ident and not kind for ident, kind in name):
        raise InvalidName()
    return name


def path_of(name: Name) -> str:
    return "/".join(name_to_string([c]) for c in name)


def _name_of(path: str) -> Name:
    try:
        return parse_name(path)
    except BAD_PARAM:
        return [(path, "")]


def _join(base: str, name: Name) -> str:
    tail = path_of(name)
    return f"{base}/{tail}" if base else tail


class Binding(NamedTuple):
    name: Name
    is_context: bool


def _put_bindings(out: CdrOutput, bindings: list[Binding]) -> None:
    out.ulong(len(bindings))
    for b in bindings:
        _put_name(out, b.name)
        out.ulong(1 if b.is_context else 0)


# ---- the service ------------------------------------------------------------------------------


class NamingService:
    """CosNaming over `table`, served by `server` (the root at `NameService`)."""

    def __init__(self, table: NameTable, server: IIOPServer) -> None:
        self.table = table
        self.server = server
        self._contexts: set[str] = set()  # made with bind_new_context
        self._lock = threading.Lock()
        self._iterators: OrderedDict[bytes, BindingIterator] = OrderedDict()
        self._iterator_ids = itertools.count(1)
        self._servants: dict[str, Context] = {}  # contexts recently used
        server.activate(Context(self, ""), ROOT_KEY)
        server.add_locator(CONTEXT_KEY, self._locate)

    def _locate(self, key: bytes) -> rpc.Servant | None:
        try:
            path = key[len(CONTEXT_KEY) :].decode()
        except UnicodeDecodeError:
            return None
        if not path:
            return None
        # Served whether or not names are below it now: a reference handed out stays valid
        # (as a persistent POA's), and a context unbound is destroyed next (nameclt's
        # remove_context) without failing.
        servant = self._servants.get(path)
        if servant is None:
            if len(self._servants) >= 1024:
                self._servants.clear()
            servant = self._servants[path] = Context(self, path)
        return servant

    def context_ior(self, path: str) -> IOR:
        key = CONTEXT_KEY + path.encode() if path else ROOT_KEY
        return self.server.ior(key, NAMING_CONTEXT_EXT)

    # ---- contexts -----------------------------------------------------------------------------

    def is_context(self, path: str) -> bool:
        if not path or path in self._contexts:
            return True
        names, _ = self.table.names(path + "/", "", 1)
        return bool(names)

    def make_context(self, path: str) -> None:
        with self._lock:
            if len(self._contexts) >= MAX_CONTEXTS:
                raise NO_RESOURCES(f"at most {MAX_CONTEXTS} naming contexts")
            self._contexts.add(path)

    def drop_context(self, path: str) -> bool:
        with self._lock:
            if path not in self._contexts:
                return False
            self._contexts.discard(path)
            return True

    def children(self, path: str) -> list[Binding]:
        """The bindings of the context at `path`, in name order (contexts first on a tie)."""
        prefix = path + "/" if path else ""
        found: dict[str, bool] = {}
        after = ""
        while len(found) < MAX_LISTED:
            names, more = self.table.names(prefix, after, PAGE)
            for full in names:
                rest = _name_of(full[len(prefix) :])
                child = path_of(rest[:1])
                found[child] = found.get(child, False) or len(rest) > 1
            if not more or not names:
                break
            after = names[-1]
        with self._lock:
            made = [c for c in self._contexts if c.startswith(prefix) and c != path]
        for c in made:
            rest = _name_of(c[len(prefix) :])
            found[path_of(rest[:1])] = True
        return [Binding(_name_of(child), ctx) for child, ctx in sorted(found.items())]

    # ---- iterators ----------------------------------------------------------------------------

    def iterator(self, rest: list[Binding]) -> IOR:
        key = ITERATOR_KEY + str(next(self._iterator_ids)).encode()
        it = BindingIterator(self, key, rest)
        with self._lock:
            if len(self._iterators) >= MAX_ITERATORS:
                old, _ = self._iterators.popitem(last=False)
                self.server.deactivate(old)
            self._iterators[key] = it
        self.server.activate(it, key)
        return self.server.ior(key, BINDING_ITERATOR)

    def iterator_done(self, key: bytes) -> None:
        with self._lock:
            self._iterators.pop(key, None)
        self.server.deactivate(key)

    # ---- resolving ----------------------------------------------------------------------------

    def resolve(self, base: str, name: Name) -> IOR:
        full = _join(base, name)
        entry = self.table.resolve(full)
        if entry is not None:
            return ior_of(entry)
        if self.is_context(full):
            return self.context_ior(full)
        raise self.not_found(base, name)

    def not_found(self, base: str, name: Name) -> NotFound:
        """Why `name` is not found in `base`: the first component missing, or bound to an
        object where a context was needed."""
        here = base
        for i in range(len(name) - 1):
            here = _join(here, name[i : i + 1])
            if self.is_context(here):
                continue
            why = NotFound.NOT_CONTEXT if self.table.resolve(here) else NotFound.MISSING_NODE
            return NotFound(why, name[i + 1 if why == NotFound.NOT_CONTEXT else i :])
        return NotFound(NotFound.MISSING_NODE, name[-1:])

    def parent_exists(self, base: str, name: Name) -> None:
        if len(name) > 1:
            parent = _join(base, name[:-1])
            if not self.is_context(parent):
                raise self.not_found(base, name)


def ior_of(entry: MiroNaming.Entry) -> IOR:
    """The reference a naming entry stands for, as an IOR."""
    if entry.endpoint.startswith("IOR:"):
        try:
            return IOR.from_string(entry.endpoint)
        except UrlError:
            pass
    from miro_gen.corba.ior import ior_from_ref

    return ior_from_ref(entry_reference(entry))


def entry_of(path: str, ior: IOR) -> MiroNaming.Entry:
    """The naming entry of `path` bound to `ior`: a miro-gen object served over ZeroMQ as
    its endpoint and key (so that ZeroMQ clients reach it as any other), anything else as its
    IOR."""
    if ior.is_nil():
        raise BAD_PARAM("a nil reference cannot be bound")
    if ior.iiop_profile() is None and ior.zmq_profile() is not None:
        ref = ref_from_ior(ior)
        return MiroNaming.Entry(path, ref.repo_id, ref.endpoint, ref.key, "")
    return MiroNaming.Entry(path, ior.type_id, ior.to_string(), b"", "")


# ---- the servants -------------------------------------------------------------------------------


def _ior_out(ior: IOR) -> CdrOutput:
    out = CdrOutput()
    ior.write(out)
    return out


class Context(HandServant):
    """The naming context at a path (the root: "")."""

    _repo_id = NAMING_CONTEXT_EXT
    _interfaces = frozenset({NAMING_CONTEXT})
    _operations: ClassVar[tuple[str, ...]] = (
        "bind", "rebind", "bind_context", "rebind_context", "resolve", "unbind",
        "new_context", "bind_new_context", "destroy", "list", "to_string", "to_name",
        "to_url", "resolve_str",
    )  # fmt: skip

    def __init__(self, service: NamingService, path: str) -> None:
        self.service = service
        self.path = path

    def _bind(self, inp: CdrInput, replace: bool) -> None:
        s = self.service
        name = _get_name(inp)
        ior = IOR.read(inp)
        s.parent_exists(self.path, name)
        full = _join(self.path, name)
        if s.is_context(full):
            if replace:
                raise NotFound(NotFound.NOT_OBJECT, name[-1:])
            raise AlreadyBound()
        if not replace and s.table.resolve(full) is not None:
            raise AlreadyBound()
        try:
            s.table.bind(entry_of(full, ior), replace)
        except MiroNaming.AlreadyBound as e:
            if replace:  # rebind declares no AlreadyBound
                raise NO_PERMISSION(f"{full} is held by {e.holder}") from None
            raise AlreadyBound() from None
        except MiroNaming.InvalidName:
            raise InvalidName() from None

    def bind(self, inp: CdrInput) -> None:
        self._bind(inp, replace=False)

    def rebind(self, inp: CdrInput) -> None:
        self._bind(inp, replace=True)

    def bind_context(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("federated naming contexts are not supported: use bind_new_context")

    rebind_context = bind_context

    def new_context(self, inp: CdrInput) -> None:
        raise NO_IMPLEMENT("a context exists at a path here: use bind_new_context")

    def resolve(self, inp: CdrInput) -> CdrOutput:
        return _ior_out(self.service.resolve(self.path, _get_name(inp)))

    def unbind(self, inp: CdrInput) -> None:
        s = self.service
        name = _get_name(inp)
        full = _join(self.path, name)
        if s.table.unbind(full):
            return
        if not s.drop_context(full):
            raise s.not_found(self.path, name)

    def bind_new_context(self, inp: CdrInput) -> CdrOutput:
        s = self.service
        name = _get_name(inp)
        s.parent_exists(self.path, name)
        full = _join(self.path, name)
        if s.is_context(full) or s.table.resolve(full) is not None:
            raise AlreadyBound()
        s.make_context(full)
        return _ior_out(s.context_ior(full))

    def destroy(self, inp: CdrInput) -> None:
        if not self.path:
            raise CORBA_SYSTEM_EXCEPTIONS["BAD_INV_ORDER"]("the root context cannot be destroyed")
        if self.service.children(self.path):
            raise NotEmpty()
        # Its binding stays until unbound, as CosNaming has it (nameclt's remove_context
        # destroys, then unbinds): a context is its path here, which the unbinding frees.

    def list(self, inp: CdrInput) -> CdrOutput:
        how_many = inp.ulong()
        found = self.service.children(self.path)
        out = CdrOutput()
        _put_bindings(out, found[:how_many])
        rest = found[how_many:]
        (self.service.iterator(rest) if rest else IOR()).write(out)
        return out

    @rpc.nonblocking
    def to_string(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        out.string(name_to_string(_get_name(inp)))
        return out

    @rpc.nonblocking
    def to_name(self, inp: CdrInput) -> CdrOutput:
        try:
            name = parse_name(inp.string("name"))
        except BAD_PARAM:
            raise InvalidName() from None
        out = CdrOutput()
        _put_name(out, name)
        return out

    @rpc.nonblocking
    def to_url(self, inp: CdrInput) -> CdrOutput:
        address, text = inp.string("address"), inp.string("name")
        if not address:
            raise InvalidAddress()
        try:
            parse_name(text)
        except BAD_PARAM:
            raise InvalidName() from None
        out = CdrOutput()
        out.string(f"corbaname:{address}#{quote(text, safe=_URL_SAFE)}")
        return out

    def resolve_str(self, inp: CdrInput) -> CdrOutput:
        try:
            name = parse_name(inp.string("name"))
        except BAD_PARAM:
            raise InvalidName() from None
        return _ior_out(self.service.resolve(self.path, name))


class BindingIterator(HandServant):
    """What a listing did not return at once."""

    _repo_id = BINDING_ITERATOR
    _operations: ClassVar[tuple[str, ...]] = ("next_one", "next_n", "destroy")

    def __init__(self, service: NamingService, key: bytes, rest: list[Binding]) -> None:
        self.service = service
        self.key = key
        self.rest = rest

    @rpc.nonblocking
    def next_one(self, inp: CdrInput) -> CdrOutput:
        out = CdrOutput()
        if self.rest:
            b = self.rest.pop(0)
            out.boolean(True)
            _put_name(out, b.name)
            out.ulong(1 if b.is_context else 0)
        else:
            out.boolean(False)
            _put_name(out, [])
            out.ulong(0)
        return out

    @rpc.nonblocking
    def next_n(self, inp: CdrInput) -> CdrOutput:
        how_many = inp.ulong()
        if how_many == 0:
            raise BAD_PARAM("next_n of 0 bindings")
        taken, self.rest = self.rest[:how_many], self.rest[how_many:]
        out = CdrOutput()
        out.boolean(bool(taken))
        _put_bindings(out, taken)
        return out

    @rpc.nonblocking
    def destroy(self, inp: CdrInput) -> None:
        self.service.iterator_done(self.key)
