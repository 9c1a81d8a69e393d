"""A CosNaming client, and names laid out as Miro's C++ Server lays them out.

`NamingContext` calls a CORBA naming service (omniNames, TAO's Naming_Service) through the IIOP
invoker: resolve, bind, rebind, unbind, bind_context, new_context, bind_new_context, destroy
and list (with its BindingIterator). `CorbaNaming` gives `Server` and `Client` what the ZeroMQ
naming client gives them: `robot1/ExampleA` is the name `[{id: robot1, kind: ""}, {id: ExampleA,
kind: ""}]` under the root context (contexts are created when missing), a plain name is looked
up in the process's naming context first and then at the root, and what is bound is an IOR
(for objects served over ZeroMQ, such as miro-gen event channels, an IOR with miro-gen's own
profile, which CORBA tools list but cannot call).
"""

from __future__ import annotations

import builtins
import contextlib
import enum
import socket
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import MiroNaming

from miro_gen.corba.bodies import call
from miro_gen.corba.connection import is_zmtp
from miro_gen.corba.ior import (
    IOR,
    CorbaName,
    UrlError,
    ior_from_ref,
    parse_name,
    parse_url,
    ref_from_ior,
)
from miro_gen.exceptions import TRANSIENT, CompletionStatus, UserException
from miro_gen.log import logger
from miro_gen.runtime import rpc
from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

_log = logger("MIRO")

NAMING_CONTEXT = "IDL:omg.org/CosNaming/NamingContext:1.0"
NAMING_CONTEXT_EXT = "IDL:omg.org/CosNaming/NamingContextExt:1.0"
_NC = "IDL:omg.org/CosNaming/NamingContext/"
TIMEOUT = 5.0  # seconds a naming call may take

Name = list[tuple[str, str]]  # (id, kind) components


class NotFoundReason(enum.IntEnum):
    missing_node = 0
    not_context = 1
    not_object = 2


@dataclass(eq=False)
class NotFound(UserException):
    why: NotFoundReason = NotFoundReason.missing_node
    rest_of_name: Name = field(default_factory=list)
    _repo_id = _NC + "NotFound:1.0"

    def __str__(self) -> str:
        return f"NotFound({self.why.name}, {'/'.join(i for i, _ in self.rest_of_name)})"


@dataclass(eq=False)
class CannotProceed(UserException):
    cxt: ObjectRef = field(default_factory=ObjectRef)
    rest_of_name: Name = field(default_factory=list)
    _repo_id = _NC + "CannotProceed:1.0"


class InvalidName(UserException):
    _repo_id = _NC + "InvalidName:1.0"


class AlreadyBound(UserException):
    _repo_id = _NC + "AlreadyBound:1.0"


class NotEmpty(UserException):
    _repo_id = _NC + "NotEmpty:1.0"


class Binding(NamedTuple):
    name: Name
    is_context: bool


def miro_name(path: str) -> Name:
    """A Miro path (`robot1/ExampleA`) as a CosNaming name: ids, empty kinds."""
    parts = [p for p in path.split("/") if p]
    if not parts:
        raise MiroNaming.InvalidName(name=path)
    return [(p, "") for p in parts]


# ---- the CosNaming::NamingContext client ------------------------------------------------------


def _put_name(out: CdrOutput, name: Name) -> None:
    out.ulong(len(name))
    for ident, kind in name:
        out.string(ident, "name id")
        out.string(kind, "name kind")


def _get_name(inp: CdrInput) -> Name:
    return [(inp.string("name id"), inp.string("name kind")) for _ in range(inp.length(8, "name"))]


class NamingContext:
    """A stub of CosNaming::NamingContext (hand-written: it is small, and needs no `any`)."""

    def __init__(self, ref: ObjectRef, invoker: Any, timeout: float = TIMEOUT) -> None:
        self.ref = ref
        self.invoker = invoker
        self.timeout = timeout

    def _call(self, op: str, out: CdrOutput | None = None) -> CdrInput:
        reply, inp = call(self.invoker, self.ref, op, out, timeout=self.timeout)
        if reply.status == rpc.ReplyStatus.USER_EXCEPTION:
            raise _user_exception(reply.repo_id, inp)
        return inp

    def _with_name(self, op: str, name: Name, ref: ObjectRef | None = None) -> CdrInput:
        out = CdrOutput()
        _put_name(out, name)
        if ref is not None:
            ior_from_ref(ref).write(out)
        return self._call(op, out)

    def resolve(self, name: Name) -> ObjectRef:
        return ref_from_ior(self.resolve_ior(name))

    def resolve_ior(self, name: Name) -> IOR:
        return IOR.read(self._with_name("resolve", name))

    def bind(self, name: Name, ref: ObjectRef) -> None:
        self._with_name("bind", name, ref)

    def rebind(self, name: Name, ref: ObjectRef) -> None:
        self._with_name("rebind", name, ref)

    def bind_context(self, name: Name, context: ObjectRef) -> None:
        self._with_name("bind_context", name, context)

    def rebind_context(self, name: Name, context: ObjectRef) -> None:
        self._with_name("rebind_context", name, context)

    def unbind(self, name: Name) -> None:
        self._with_name("unbind", name)

    def new_context(self) -> NamingContext:
        ref = ref_from_ior(IOR.read(self._call("new_context")))
        return NamingContext(ref, self.invoker, self.timeout)

    def bind_new_context(self, name: Name) -> NamingContext:
        ref = ref_from_ior(IOR.read(self._with_name("bind_new_context", name)))
        return NamingContext(ref, self.invoker, self.timeout)

    def destroy(self) -> None:
        self._call("destroy")

    def list(self, how_many: int = 1000) -> builtins.list[Binding]:
        """Every binding of this context (following its BindingIterator to the end)."""
        out = CdrOutput()
        out.ulong(how_many)
        inp = self._call("list", out)
        found = _bindings(inp)
        iterator = ref_from_ior(IOR.read(inp))
        while iterator:
            out = CdrOutput()
            out.ulong(how_many)
            it = NamingContext(iterator, self.invoker, self.timeout)
            res = it._call("next_n", out)
            more = res.boolean()
            found += _bindings(res)
            if not more:
                with contextlib.suppress(Exception):  # the iterator is gone anyway
                    it._call("destroy")
                break
        return found

    def context(self, name: Name) -> NamingContext:
        return NamingContext(self.resolve(name), self.invoker, self.timeout)


def _bindings(inp: CdrInput) -> list[Binding]:
    return [Binding(_get_name(inp), inp.ulong() == 1) for _ in range(inp.length(8, "bindings"))]


def _user_exception(rid: str, inp: CdrInput) -> UserException:
    if rid == NotFound._repo_id:
        why = inp.ulong()
        return NotFound(
            NotFoundReason(why) if why < 3 else NotFoundReason.missing_node, _get_name(inp)
        )
    if rid == CannotProceed._repo_id:
        return CannotProceed(ref_from_ior(IOR.read(inp)), _get_name(inp))
    for cls in (InvalidName, AlreadyBound, NotEmpty):
        if rid == cls._repo_id:
            return cls()
    return UserException(f"the naming service raised {rid}")


# ---- Miro's layout ------------------------------------------------------------------------------


@dataclass(slots=True)
class CorbaEntry(MiroNaming.Entry):
    """A naming entry found in a CORBA naming service, with the reference as it came."""

    ref: ObjectRef = field(default_factory=ObjectRef)


class CorbaNaming:
    """Binds and resolves names for a process whose naming context is `context`, in a CORBA
    naming service whose root context is `root` (the same calls as the ZeroMQ naming client)."""

    leased = False  # bindings live until unbound: CosNaming has no leases

    def __init__(self, invoker: Any, root: ObjectRef, context: str, url: str = "") -> None:
        self.invoker = invoker
        self.root = NamingContext(root, invoker)
        self.context = context
        self.url = url

    def full_name(self, name: str) -> str:
        return name if "/" in name else f"{self.context}/{name}"

    def resolve(self, name: str) -> CorbaEntry:
        """The entry of `name`: a path as it is; a plain name in this process's context first,
        then at the root. MiroNaming.NotFound names what was looked for."""
        paths = [name] if "/" in name else [f"{self.context}/{name}", name]
        for path in paths:
            try:
                ior = self.root.resolve_ior(miro_name(path))
            except NotFound:
                continue
            except (InvalidName, CannotProceed):
                raise MiroNaming.InvalidName(name=path) from None
            return _entry(path, ior)
        raise MiroNaming.NotFound(name=paths[0])

    def rebind(self, entry: MiroNaming.Entry) -> ObjectRef:
        """Bind the entry's reference (a CorbaEntry's, else one made of its endpoint and key)
        at its path, making the contexts on the way when missing; the reference bound."""
        ref = getattr(entry, "ref", None) or entry_reference(entry)
        name = miro_name(entry.name)
        context = self.root
        for i in range(len(name) - 1):
            try:
                context = context.context(name[i : i + 1])
            except NotFound:
                try:
                    context = context.bind_new_context(name[i : i + 1])
                except AlreadyBound:  # another process made it meanwhile
                    context = context.context(name[i : i + 1])
        context.rebind(name[-1:], ref)
        return ref

    def unbind(self, path: str) -> None:
        try:
            self.root.unbind(miro_name(path))
        except NotFound:
            raise MiroNaming.NotFound(name=path) from None

    def entries(self, prefix: str = "") -> builtins.list[CorbaEntry]:
        """The objects bound under `prefix` (all, for ""), as entries, in name order."""
        found: list[CorbaEntry] = []
        self._walk(self.root, [], found, depth=0)
        return sorted((e for e in found if e.name.startswith(prefix)), key=lambda e: e.name)

    def _walk(
        self,
        context: NamingContext,
        path: builtins.list[str],
        found: builtins.list[CorbaEntry],
        depth: int,
    ) -> None:
        for binding in context.list():
            ident = ".".join(p for p in binding.name[0] if p)
            here = [*path, ident]
            if binding.is_context and depth < 16:
                try:
                    self._walk(context.context(binding.name), here, found, depth + 1)
                except Exception as e:  # a context on a server that is gone: listed as such
                    _log.debug("cannot list %s: %s", "/".join(here), e)
            elif not binding.is_context:
                try:
                    found.append(_entry("/".join(here), context.resolve_ior(binding.name)))
                except Exception:
                    found.append(CorbaEntry("/".join(here), "", "", b"", ""))


def _entry(path: str, ior: IOR) -> CorbaEntry:
    ref = ref_from_ior(ior)
    return CorbaEntry(path, ref.repo_id, ref.endpoint, ref.key, _miro_type_hash(ior), ref)


def entry_reference(entry: MiroNaming.Entry) -> ObjectRef:
    """The reference a naming entry of miro-gen's stands for (an object served over ZeroMQ
    with its type hash in its profile)."""
    from miro_gen.corba.ior import CorbaRef

    ref = ObjectRef(entry.repo_id, entry.endpoint, entry.key)
    if entry.type_hash and not entry.endpoint.startswith("iiop://"):
        ior = _with_type_hash(ior_from_ref(ref), entry.type_hash)
        tagged = CorbaRef(*ref)
        tagged.ior = ior
        return tagged
    return ref


def _with_type_hash(ior: IOR, type_hash: str) -> IOR:
    from miro_gen.corba.ior import TAG_MIRO_ZMQ, Profile
    from miro_gen.runtime.cdrstream import encapsulated

    profiles = []
    for p in ior.profiles:
        if p.tag == TAG_MIRO_ZMQ:
            zmq = ior.zmq_profile()
            assert zmq is not None
            out = encapsulated()
            out.string(zmq[0])
            out.octets(zmq[1])
            out.string(type_hash)
            p = Profile(TAG_MIRO_ZMQ, out.getvalue())
        profiles.append(p)
    return IOR(ior.type_id, profiles)


def _miro_type_hash(ior: IOR) -> str:
    from miro_gen.corba.ior import TAG_MIRO_ZMQ
    from miro_gen.runtime.cdrstream import encapsulation_input

    for p in ior.profiles:
        if p.tag == TAG_MIRO_ZMQ:
            try:
                inp = encapsulation_input(p.data)
                inp.string()
                inp.octets()
                return inp.string() if inp.left() else ""
            except Exception:
                return ""
    return ""


# ---- which naming service ------------------------------------------------------------------


class Peer(enum.Enum):
    ZMQ = "zmq"
    GIOP = "giop"
    NONE = "none"  # nothing answers (yet)


def probe(host: str, port: int, key: bytes = b"NameService", timeout: float = 1.0) -> Peer:
    """What listens at HOST:PORT: a ZeroMQ peer greets a new connection with ZMTP's signature at
    once; a GIOP one stays silent until asked, and answers a LocateRequest."""
    from miro_gen.corba import giop

    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except OSError:
        return Peer.NONE
    try:
        sock.settimeout(min(0.3, timeout))
        try:
            first = sock.recv(16)
            if is_zmtp(first):
                return Peer.ZMQ
            if not first:
                return Peer.NONE
        except TimeoutError:
            pass
        sock.settimeout(timeout)
        sock.sendall(giop.encode_locate_request(2, 1, key))
        deadline = time.monotonic() + timeout
        data = b""
        while len(data) < 12 and time.monotonic() < deadline:
            chunk = sock.recv(64)
            if not chunk:
                break
            data += chunk
        if data[:4] == giop.MAGIC:
            return Peer.GIOP
        return Peer.ZMQ if is_zmtp(data) else Peer.NONE
    except OSError:
        return Peer.NONE
    finally:
        sock.close()


def root_reference(url: str) -> tuple[ObjectRef, str]:
    """The root context's reference for a naming-service URL, and the name the URL adds
    (corbaname: `#a/b` resolves a context below the root)."""
    try:
        parsed = parse_url(url.removeprefix("NameService="), NAMING_CONTEXT)
    except UrlError as e:
        raise TRANSIENT(str(e), completed=CompletionStatus.NO) from None
    if isinstance(parsed, CorbaName):
        return ref_from_ior(parsed.context), parsed.name
    return ref_from_ior(parsed), ""


def decide(url: str, timeout: float = 1.0) -> Peer:
    """Whether the naming service of `url` is a CORBA one: an IOR always is; a corbaloc or
    iioploc URL is whatever answers at its address (the manual's `iioploc://` URLs name
    `miro naming` as often as omniNames)."""
    if url.strip()[:4].upper() == "IOR:":
        return Peer.GIOP
    ref, _ = root_reference(url)
    ior = ior_from_ref(ref)
    profile = ior.iiop_profile()
    if profile is None:
        return Peer.GIOP
    return probe(profile.host, profile.port, profile.key, timeout)


def corba_naming(invoker: Any, url: str, context: str) -> CorbaNaming:
    """The CorbaNaming of `url` (its root context, or for corbaname the context it names)."""
    ref, below = root_reference(url)
    naming = CorbaNaming(invoker, ref, context, url)
    if below:
        naming.root = naming.root.context(parse_name(below))
    return naming


def explain_unreachable(endpoint: str, error: TRANSIENT) -> TRANSIENT:
    """`error` (a ZeroMQ naming service at `endpoint`, tcp://HOST:PORT, did not answer), made
    clear when a CORBA naming service is what listens there."""
    host, _, port = endpoint.removeprefix("tcp://").rpartition(":")
    if not port.isdigit() or probe(host.strip("[]"), int(port), timeout=0.5) != Peer.GIOP:
        return error
    return TRANSIENT(
        f"{endpoint} is a CORBA naming service (it speaks GIOP), not a miro naming service: "
        f"use --naming corbaloc:iiop:{host}:{port}/NameService",
        completed=CompletionStatus.NO,
    )


def resolve_url(invoker: Any, url: str) -> ObjectRef:
    """The object an IOR, corbaloc or corbaname URL names (a corbaname is resolved)."""
    try:
        parsed = parse_url(url)
    except UrlError as e:
        raise TRANSIENT(str(e), completed=CompletionStatus.NO) from None
    if isinstance(parsed, CorbaName):
        context = NamingContext(ref_from_ior(parsed.context), invoker)
        return context.resolve(parse_name(parsed.name))
    return ref_from_ior(parsed)
