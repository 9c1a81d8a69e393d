"""Interoperable object references: IORs, IIOP profiles, and the URLs that name objects.

An IOR is a repository id and a list of tagged profiles; the one that matters here is the IIOP
profile (tag 0): the GIOP version, a host, a port, the object key and tagged components (code
sets, ORB type, alternate addresses). Stringified, an IOR is `IOR:` and the hex of its CDR
encapsulation. The URL forms accepted are those of the Interoperable Naming Service:

* `corbaloc:iiop:1.2@HOST:PORT,:HOST2:PORT2/KEY` (the protocol may be empty: `corbaloc::HOST/KEY`;
  no port means 2809; the key is URL-escaped);
* `corbaname:iiop:HOST:PORT/KEY#a/b.kind` (a naming context, `NameService` by default, and a
  stringified name to resolve in it);
* `iioploc://HOST:PORT/KEY` and `iiopname://HOST:PORT/KEY#name`, the older spellings TAO and the
  Miro manual use.

References to objects served over ZeroMQ travel as IORs too, with a profile of miro-gen's own
(`TAG_MIRO_ZMQ`: endpoint and key), which every ORB carries along without using.
"""

from __future__ import annotations

import binascii
import re
from dataclasses import dataclass, field
from typing import NamedTuple
from urllib.parse import quote_from_bytes, unquote_to_bytes

from miro_gen.exceptions import BAD_PARAM, MARSHAL
from miro_gen.runtime.cdr import ForeignBody, ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput, encapsulated, encapsulation_input

TAG_INTERNET_IOP = 0
TAG_MULTIPLE_COMPONENTS = 1
TAG_MIRO_ZMQ = 0x4D495230  # "MIR0": an object served over ZeroMQ (endpoint, key)

TAG_ORB_TYPE = 0
TAG_CODE_SETS = 1
TAG_ALTERNATE_IIOP_ADDRESS = 3

ORB_TYPE_MIRO = 0x4D49524F  # "MIRO"
CODESET_ISO8859_1 = 0x00010001
CODESET_UTF8 = 0x05010001
CODESET_UTF16 = 0x00010109

DEFAULT_PORT = 2809  # the port corbaloc implies when none is given
DEFAULT_KEY = b"NameService"  # the key corbaname implies


class UrlError(ValueError):
    """A string that is not an object reference or URL this module can read."""


class Component(NamedTuple):
    tag: int
    data: bytes


class Profile(NamedTuple):
    tag: int
    data: bytes


@dataclass
class IIOPProfile:
    """The body of an IIOP profile (tag 0)."""

    host: str
    port: int
    key: bytes
    version: tuple[int, int] = (1, 2)
    components: list[Component] = field(default_factory=list)

    def encode(self) -> bytes:
        out = encapsulated()
        out.octet(self.version[0])
        out.octet(self.version[1])
        out.string(self.host, "IIOP host")
        out.ushort(self.port)
        out.octets(self.key, "object key")
        if self.version >= (1, 1):
            out.ulong(len(self.components))
            for c in self.components:
                out.ulong(c.tag)
                out.octets(c.data, "tagged component")
        return out.getvalue()

    @classmethod
    def decode(cls, data: bytes) -> IIOPProfile:
        inp = encapsulation_input(data, "IIOP profile")
        version = (inp.octet(), inp.octet())
        if version[0] != 1:
            raise MARSHAL(f"IIOP profile of version {version[0]}.{version[1]}")
        host = inp.string("IIOP host")
        port = inp.ushort()
        key = inp.octets("object key")
        components = []
        if version[1] >= 1 and inp.left() >= 4:
            for _ in range(inp.length(8, "tagged components")):
                components.append(Component(inp.ulong(), inp.octets("tagged component")))
        return cls(host, port, key, version, components)

    def component(self, tag: int) -> bytes | None:
        return next((c.data for c in self.components if c.tag == tag), None)

    def addresses(self) -> list[tuple[str, int]]:
        """The host and port, then any alternate addresses the profile lists."""
        found = [(self.host, self.port)]
        for c in self.components:
            if c.tag == TAG_ALTERNATE_IIOP_ADDRESS:
                try:
                    inp = encapsulation_input(c.data)
                    found.append((inp.string("host"), inp.ushort()))
                except MARSHAL:
                    continue
        return found


@dataclass
class CodeSets:
    """What a TAG_CODE_SETS component says: native and conversion code sets for char and wchar."""

    char_native: int = CODESET_ISO8859_1
    char_conversion: tuple[int, ...] = ()
    wchar_native: int = 0
    wchar_conversion: tuple[int, ...] = ()

    def encode(self) -> bytes:
        out = encapsulated()
        for native, conversion in (
            (self.char_native, self.char_conversion),
            (self.wchar_native, self.wchar_conversion),
        ):
            out.ulong(native)
            out.ulong(len(conversion))
            for c in conversion:
                out.ulong(c)
        return out.getvalue()

    @classmethod
    def decode(cls, data: bytes) -> CodeSets:
        inp = encapsulation_input(data, "code sets")
        parts: list[int | tuple[int, ...]] = []
        for _ in range(2):
            parts.append(inp.ulong())
            parts.append(tuple(inp.ulong() for _ in range(inp.length(4, "code sets"))))
        return cls(*parts)  # type: ignore[arg-type]


# Our own IORs: UTF-8 strings (what generated code writes), UTF-16 wide characters.
OUR_CODE_SETS = CodeSets(CODESET_UTF8, (), CODESET_UTF16, ())


def our_components() -> list[Component]:
    orb = CdrOutput(bytearray(b"\x01"))
    orb.ulong(ORB_TYPE_MIRO)
    return [
        Component(TAG_ORB_TYPE, orb.getvalue()),
        Component(TAG_CODE_SETS, OUR_CODE_SETS.encode()),
    ]


@dataclass
class IOR:
    """An interoperable object reference: a repository id and tagged profiles."""

    type_id: str = ""
    profiles: list[Profile] = field(default_factory=list)

    # ---- making and reading -----------------------------------------------------------------

    @classmethod
    def iiop(
        cls,
        type_id: str,
        host: str,
        port: int,
        key: bytes,
        version: tuple[int, int] = (1, 2),
        components: list[Component] | None = None,
    ) -> IOR:
        comps = our_components() if components is None else components
        body = IIOPProfile(host, port, key, version, comps)
        return cls(type_id, [Profile(TAG_INTERNET_IOP, body.encode())])

    def is_nil(self) -> bool:
        return not self.profiles

    def iiop_profile(self) -> IIOPProfile | None:
        """The first IIOP profile that decodes (None when there is none)."""
        for p in self.profiles:
            if p.tag == TAG_INTERNET_IOP:
                try:
                    return IIOPProfile.decode(p.data)
                except MARSHAL:
                    continue
        return None

    def zmq_profile(self) -> tuple[str, bytes] | None:
        for p in self.profiles:
            if p.tag == TAG_MIRO_ZMQ:
                try:
                    inp = encapsulation_input(p.data, "miro profile")
                    return inp.string("endpoint"), inp.octets("key")
                except MARSHAL:
                    continue
        return None

    # ---- CDR ----------------------------------------------------------------------------------

    def write(self, out: CdrOutput) -> None:
        out.string(self.type_id, "IOR type id")
        out.ulong(len(self.profiles))
        for p in self.profiles:
            out.ulong(p.tag)
            out.octets(p.data, "IOR profile")

    @classmethod
    def read(cls, inp: CdrInput) -> IOR:
        type_id = inp.string("IOR type id")
        profiles = [
            Profile(inp.ulong(), inp.octets("IOR profile"))
            for _ in range(inp.length(8, "IOR profiles"))
        ]
        return cls(type_id, profiles)

    def encode(self) -> bytes:
        """This IOR in little-endian CDR, for a 4-aligned place in a stream."""
        out = CdrOutput()
        self.write(out)
        return out.getvalue()

    def to_string(self) -> str:
        out = encapsulated()
        self.write(out)
        return "IOR:" + out.getvalue().hex()

    @classmethod
    def from_string(cls, text: str) -> IOR:
        body = text.strip()[4:]
        try:
            data = binascii.unhexlify(body)
        except (binascii.Error, ValueError):
            raise UrlError("a stringified IOR is 'IOR:' and an even number of hex digits") from None
        try:
            inp = encapsulation_input(data, "IOR")
            ior = cls.read(inp)
        except MARSHAL as e:
            raise UrlError(f"the IOR does not decode: {e.message}") from None
        return ior

    def describe(self) -> str:
        """One line for messages: the type and where the object is."""
        p = self.iiop_profile()
        where = f"{p.host}:{p.port}" if p is not None else "no IIOP address"
        return f"{self.type_id or 'Object'} at {where}"


# ---- URLs ---------------------------------------------------------------------------------------

_ADDR = re.compile(
    r"^(?:(?P<proto>iiop)?:)?(?:(?P<major>\d+)\.(?P<minor>\d+)@)?"
    r"(?P<host>\[[^\]]*\]|[^:/\[\],]*)(?::(?P<port>\d*))?$"
)


class CorbaName(NamedTuple):
    """A corbaname URL: the naming context's reference, and the name to resolve in it."""

    context: IOR
    name: str


def parse_url(text: str, type_id: str = "") -> IOR | CorbaName:
    """An `IOR:`, `corbaloc:`, `iioploc://`, `corbaname:` or `iiopname://` string, read.
    `UrlError` says what is wrong with anything else."""
    t = text.strip()
    low = t.lower()
    if low.startswith("ior:"):
        return IOR.from_string(t)
    if low.startswith("corbaloc:"):
        return _corbaloc(t[len("corbaloc:") :], type_id, text)
    if low.startswith("iioploc://"):
        return _corbaloc(t[len("iioploc://") :], type_id, text)
    if low.startswith("corbaname:") or low.startswith("iiopname://"):
        rest = t[len("corbaname:") :] if low.startswith("corbaname:") else t[len("iiopname://") :]
        loc, _, name = rest.partition("#")
        if "/" not in loc:
            loc += "/NameService"
        context = _corbaloc(loc, "IDL:omg.org/CosNaming/NamingContext:1.0", text)
        return CorbaName(context, unquote_to_bytes(name).decode("utf-8", "replace"))
    raise UrlError(
        f"{text!r} is not an object reference: expected IOR:..., corbaloc:iiop:HOST:PORT/KEY, "
        "iioploc://HOST:PORT/KEY or corbaname:iiop:HOST:PORT#NAME"
    )


def _corbaloc(body: str, type_id: str, text: str) -> IOR:
    addrs, slash, key_text = body.partition("/")
    if not slash:
        raise UrlError(f"{text!r}: the object key is missing (.../KEY)")
    if addrs.startswith("rir:") or addrs == "rir":
        raise UrlError(f"{text!r}: corbaloc:rir: refers to an ORB's own initial references")
    profiles: list[IIOPProfile] = []
    for part in addrs.split(","):
        m = _ADDR.match(part)
        if m is None or not m.group("host"):
            raise UrlError(f"{text!r}: cannot read the address {part!r} (expected HOST:PORT)")
        host = m.group("host").strip("[]")
        port = int(m.group("port") or DEFAULT_PORT)
        if not 0 < port < 65536:
            raise UrlError(f"{text!r}: port {port} is out of range")
        # The INS says a corbaloc without a version means 1.0; every current ORB speaks 1.2,
        # and 1.2 is what they use for such URLs too.
        version = (int(m.group("major")), int(m.group("minor"))) if m.group("major") else (1, 2)
        if version[0] != 1 or version[1] > 3:
            raise UrlError(f"{text!r}: unknown IIOP version {version[0]}.{version[1]}")
        profiles.append(IIOPProfile(host, port, b"", version))
    key = unquote_to_bytes(key_text)
    first = profiles[0]
    components = [
        Component(TAG_ALTERNATE_IIOP_ADDRESS, _alternate(p.host, p.port)) for p in profiles[1:]
    ]
    return IOR.iiop(type_id, first.host, first.port, key, first.version, components)


def _alternate(host: str, port: int) -> bytes:
    out = encapsulated()
    out.string(host)
    out.ushort(port)
    return out.getvalue()


def corbaloc(host: str, port: int, key: bytes) -> str:
    """The corbaloc URL of an object at HOST:PORT with KEY."""
    h = f"[{host}]" if ":" in host else host
    return f"corbaloc:iiop:1.2@{h}:{port}/{quote_from_bytes(key, safe='/-_.~')}"


# ---- names ------------------------------------------------------------------------------------


def parse_name(text: str) -> list[tuple[str, str]]:
    """A stringified CosNaming name (`a/b.kind`, `\\` escapes `/`, `.` and itself), as
    (id, kind) pairs."""
    if not text:
        raise BAD_PARAM("an empty name")
    parts: list[tuple[str, str]] = []
    current = [""]
    i = 0
    while i < len(text):
        c = text[i]
        if c == "\\" and i + 1 < len(text):
            current[-1] += text[i + 1]
            i += 2
            continue
        if c == "/":
            parts.append(_component(current, text))
            current = [""]
        elif c == "." and len(current) == 1:
            current.append("")
        else:
            current[-1] += c
        i += 1
    parts.append(_component(current, text))
    return parts


def _component(current: list[str], text: str) -> tuple[str, str]:
    ident = current[0]
    kind = current[1] if len(current) > 1 else ""
    if not ident and not kind:
        raise BAD_PARAM(f"the name {text!r} has an empty component")
    return ident, kind


def name_to_string(name: list[tuple[str, str]]) -> str:
    def esc(s: str) -> str:
        return s.replace("\\", "\\\\").replace("/", "\\/").replace(".", "\\.")

    return "/".join(esc(i) + ("." + esc(k) if k else "") for i, k in name)


# ---- object references --------------------------------------------------------------------------


class CorbaRef(ObjectRef):
    """An object reference that came as an IOR: as an `ObjectRef` its endpoint is
    `iiop://HOST:PORT` and its key the object key; the whole IOR is kept (`ior`) so that the
    reference goes back to CORBA peers exactly as it came."""

    ior: IOR


def iiop_endpoint(host: str, port: int) -> str:
    return f"iiop://[{host}]:{port}" if ":" in host else f"iiop://{host}:{port}"


def parse_iiop_endpoint(endpoint: str) -> tuple[str, int]:
    """HOST and PORT of `iiop://HOST:PORT`."""
    m = re.match(r"^iiop://(\[[^\]]+\]|[^:/\[\]]+):(\d+)$", endpoint)
    if m is None:
        raise BAD_PARAM(f"not an IIOP endpoint: {endpoint!r}")
    return m.group(1).strip("[]"), int(m.group(2))


def ref_from_ior(ior: IOR) -> ObjectRef:
    """The `ObjectRef` for an IOR received: a `CorbaRef` for a CORBA object, a plain reference
    for one of ours served over ZeroMQ, the nil reference for a nil IOR."""
    if ior.is_nil():
        return ObjectRef()
    zmq = ior.zmq_profile()
    profile = ior.iiop_profile()
    if zmq is not None and profile is None:
        return ObjectRef(ior.type_id, zmq[0], zmq[1])
    if profile is not None:
        ref = CorbaRef(ior.type_id, iiop_endpoint(profile.host, profile.port), profile.key)
    else:  # profiles we cannot use (SSL only, another transport): kept whole
        ref = CorbaRef(ior.type_id, ior.to_string(), b"")
    ref.ior = ior
    return ref


def ior_from_ref(ref: ObjectRef) -> IOR:
    """The IOR a reference travels as to a CORBA peer."""
    if not ref:
        return IOR()
    ior = getattr(ref, "ior", None)
    if isinstance(ior, IOR):
        return ior
    if ref.endpoint.startswith("iiop://"):
        host, port = parse_iiop_endpoint(ref.endpoint)
        return IOR.iiop(ref.repo_id, host, port, ref.key)
    if ref.endpoint[:4].upper() == "IOR:":
        try:
            return IOR.from_string(ref.endpoint)
        except UrlError as e:
            raise BAD_PARAM(str(e)) from None
    out = encapsulated()
    out.string(ref.endpoint)
    out.octets(ref.key)
    return IOR(ref.repo_id, [Profile(TAG_MIRO_ZMQ, out.getvalue())])


class GiopBody(ForeignBody):
    """A request or reply body that came in a GIOP message: its object references are IORs
    (generated decoders call `get_object` for them)."""

    def get_object(self, off: int, e: int, what: str) -> tuple[ObjectRef, int]:
        inp = CdrInput(self, off, e)
        try:
            ior = IOR.read(inp)
        except MARSHAL as x:
            raise MARSHAL(f"{what}: {x.message}") from None
        return ref_from_ior(ior), inp.pos
