"""Reply bodies between GIOP and the transport-neutral `Reply` of `miro_gen.runtime.rpc`.

Generated stubs and skeletons read and write bodies that begin with a 4-byte encapsulation
header and hold the values aligned relative to its end. A GIOP 1.2 body starts at a multiple
of 8 in its message, so for plain results the two are the same bytes; a body that begins
elsewhere (GIOP 1.0/1.1, a user exception's members after its repository id) is handed over
after zero bytes that keep its values where they were modulo 8 (`body_in`, read from
`cdr.body_start`). What differs is around them: a system exception is a repository id,
a minor code and a completion status (its message travels in a service context of ours, which
other ORBs ignore), and object references are IORs (a `GiopBody` decodes them as such).
"""

from __future__ import annotations

from typing import Any, Final

from miro_gen import exceptions as exc
from miro_gen.corba import anys
from miro_gen.corba.giop import SC_MIRO_DETAIL, Contexts, ReplyStatus, context
from miro_gen.corba.ior import GiopBody
from miro_gen.exceptions import MARSHAL, UNKNOWN, CompletionStatus, SystemException
from miro_gen.runtime import cdr, registry, rpc
from miro_gen.runtime.cdr import BE, LE, ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput, encapsulated, encapsulation_input

_HEADERS: Final = (b"\x00\x00\x00\x00", b"\x00\x01\x00\x00")  # big-, little-endian


def body_in(msg: bytes, offset: int, little: bool) -> GiopBody:
    """The body at `offset` of a message, as generated decoders read it. A GIOP 1.0/1.1 body
    follows its header at once, so it may begin anywhere: zero bytes after the encapsulation
    header keep its values where they were modulo 8 (`cdr.body_start`)."""
    pad = offset % 8
    body = GiopBody(_HEADERS[little] + bytes(pad) + msg[offset:])
    if pad:
        body.start = 4 + pad
    return body


def body_taken(msg: bytearray, offset: int, little: bool) -> GiopBody:
    """`body_in` for a message whose bytes the caller gives up (a large one): the header and
    padding are written over the bytes before the body (the request header, already read), so
    that the body is copied once, not twice."""
    pad = offset % 8
    at = offset - 4 - pad
    if at < 0:
        return body_in(bytes(msg), offset, little)
    msg[at : at + 4] = _HEADERS[little]
    msg[at + 4 : offset] = bytes(pad)
    body = GiopBody(memoryview(msg)[at:])
    if pad:
        body.start = 4 + pad
    return body


def body_input(body: bytes) -> CdrInput:
    """A stream over the values of a request or reply body, for hand-written readers."""
    return CdrInput(bytes(body[4:]), cdr.body_start(body) - 4, LE if body[1] == 1 else BE)


# ---- system exceptions -----------------------------------------------------------------------

# CORBA's standard system exceptions beyond those miro_gen.exceptions defines, so that what a
# CORBA peer raises arrives as itself (registered where replies are decoded).
_STANDARD = [
    "NO_MEMORY", "IMP_LIMIT", "INV_OBJREF", "NO_PERMISSION", "INTERNAL", "INITIALIZE",
    "BAD_TYPECODE", "NO_RESOURCES", "NO_RESPONSE", "PERSIST_STORE", "BAD_INV_ORDER",
    "FREE_MEM", "INV_IDENT", "INV_FLAG", "INTF_REPOS", "BAD_CONTEXT", "OBJ_ADAPTER",
    "DATA_CONVERSION", "TRANSACTION_REQUIRED", "TRANSACTION_ROLLEDBACK", "INVALID_TRANSACTION",
    "INV_POLICY", "CODESET_INCOMPATIBLE", "REBIND", "TRANSACTION_UNAVAILABLE",
    "TRANSACTION_MODE", "BAD_QOS", "INVALID_ACTIVITY", "ACTIVITY_COMPLETED",
    "ACTIVITY_REQUIRED",
]  # fmt: skip
CORBA_SYSTEM_EXCEPTIONS: dict[str, type[SystemException]] = {}
for _name in _STANDARD:
    _repo = f"IDL:omg.org/CORBA/{_name}:1.0"
    _cls = exc.SYSTEM_EXCEPTIONS.get(_repo)
    if _cls is None:
        _cls = type(_name, (SystemException,), {"_repo_id": _repo, "__module__": __name__})
        exc.SYSTEM_EXCEPTIONS[_repo] = _cls
    CORBA_SYSTEM_EXCEPTIONS[_name] = _cls
CORBA_SYSTEM_EXCEPTIONS.update({c.__name__: c for c in exc.SYSTEM_EXCEPTIONS.values()})


def system_reply(repo_id: str, minor: int, completed: int, message: str) -> rpc.Reply:
    """A `Reply` carrying a system exception with any repository id."""
    cls = exc.SYSTEM_EXCEPTIONS.get(repo_id)
    if cls is None:  # a vendor's own: reported as UNKNOWN, naming it
        message = f"{repo_id}: {message}"
        repo_id = UNKNOWN._repo_id
        cls = UNKNOWN
    try:
        status = CompletionStatus(completed)
    except ValueError:
        status = CompletionStatus.MAYBE
    return rpc.system_exception_reply(cls(message, minor, status))


def system_exception_in(
    msg: bytes, offset: int, little: bool, contexts: Contexts, peer: str
) -> rpc.Reply:
    inp = CdrInput(msg, offset, LE if little else BE)
    repo_id = inp.string("system exception id")
    minor = inp.ulong()
    completed = inp.ulong()
    detail = context(contexts, SC_MIRO_DETAIL)
    message = ""
    if detail is not None:
        try:
            message = encapsulation_input(detail).string("exception detail")
        except MARSHAL:
            message = ""
    if not message:
        message = f"raised by the CORBA server at {peer} (minor code {minor:#x})"
    return system_reply(repo_id, minor, completed, message)


def system_exception_out(reply: rpc.Reply) -> tuple[bytes, Contexts]:
    """The GIOP body and service contexts of a system exception reply of ours."""
    try:
        rpc.raise_system_exception(reply)
    except SystemException as raised:
        error = raised
    out = CdrOutput()
    out.string(reply.repo_id if reply.repo_id.startswith("IDL:") else UNKNOWN._repo_id)
    out.ulong(error.minor & 0xFFFFFFFF)
    out.ulong(int(error.completed))
    detail = encapsulated()
    detail.string(error.message)
    return out.getvalue(), [(SC_MIRO_DETAIL, detail.getvalue())]


# ---- user exceptions ---------------------------------------------------------------------------


def user_exception_in(msg: bytes, offset: int, little: bool) -> rpc.Reply:
    """A user exception's GIOP body as the body its generated class decodes: its members,
    which follow its repository id (so they may begin 4 bytes off a multiple of 8)."""
    inp = CdrInput(msg, offset, LE if little else BE)
    repo_id = inp.string("exception id")
    return rpc.Reply(rpc.ReplyStatus.USER_EXCEPTION, body_in(msg, inp.pos, little), repo_id)


def user_exception_out(reply: rpc.Reply) -> bytes:
    """The GIOP body of a user exception reply of ours: its id, then its members."""
    out = CdrOutput()
    out.string(reply.repo_id, "exception id")
    cls = registry.find_repo_id(reply.repo_id)
    if cls is None:  # pragma: no cover - the servant raised an instance: its class is imported
        out.raw(memoryview(reply.body)[4:])
        return out.getvalue()
    tc = anys.typecode_for(cls)
    if len(out.buf) % 8 == 0 and not anys.has_refs(tc):
        out.raw(memoryview(reply.body)[4:])
    else:
        src = CdrInput(bytes(reply.body[4:]), 0, cdr.header_endianness(reply.body))
        anys.transcode(tc, src, out, anys.MIRO_REFS, anys.GIOP_REFS)
    return out.getvalue()


def reply_out(reply: rpc.Reply) -> tuple[ReplyStatus, bytes | memoryview, Contexts]:
    """GIOP reply status, body and service contexts for a reply of ours."""
    if reply.status == rpc.ReplyStatus.OK:
        return ReplyStatus.NO_EXCEPTION, memoryview(reply.body)[4:], []
    if reply.status == rpc.ReplyStatus.USER_EXCEPTION:
        try:
            return ReplyStatus.USER_EXCEPTION, user_exception_out(reply), []
        except SystemException as e:
            reply = rpc.system_exception_reply(
                UNKNOWN(
                    f"{reply.repo_id} could not be sent: {e.message}",
                    completed=CompletionStatus.YES,
                )
            )
    body, contexts = system_exception_out(reply)
    return ReplyStatus.SYSTEM_EXCEPTION, body, contexts


# ---- hand-written stubs -------------------------------------------------------------------------


def call(
    invoker: Any,
    ref: ObjectRef,
    operation: str,
    args: CdrOutput | None = None,
    *,
    timeout: float = 10.0,
    oneway: bool = False,
) -> tuple[rpc.Reply, CdrInput]:
    """Invoke `operation` with arguments written on `args` (laid out from a multiple of 8) for
    the stubs this package writes by hand (CosNaming, CosEvent): the reply, and a stream over
    its body. System exceptions are raised; a user exception's reply is returned for the
    caller to decode (its status says so)."""
    body = _HEADERS[1] + (args.buf if args is not None else b"")
    reply = invoker.invoke(ref, operation, body, oneway=oneway, timeout=timeout)
    if reply is None:
        return rpc.Reply(rpc.ReplyStatus.OK, b""), CdrInput(b"")
    if reply.status == rpc.ReplyStatus.SYSTEM_EXCEPTION:
        rpc.raise_system_exception(reply)
    return reply, body_input(reply.body)
