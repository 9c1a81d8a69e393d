"""The key expressions of the Zenoh backbone: one owner of their layout.

    miro/call/<owner>/<zid>      the queryable of one process's objects (its session id)
    miro/@registry/<owner>       the naming registry's binding operations asked by the
                                 sessions of one certificate (`<owner>`: its common name);
                                 the router's session answers for every owner (`REGISTRY_KEYS`)
    miro/alive/<owner>/<zid>     liveliness: that process is up
    miro/name/<owner>/<zid>/<name>   liveliness: a name it keeps bound (the registry drops
                                 the name when the token goes: its process died or was cut off)
    miro/ev/<channel>/<domain>/<type>   the events of one channel, domain and type
    miro/sub/<channel>/<prefix>/<keep>/<zid>/<n>   liveliness: a consumer's subscription (its
                                 prefix, transport.events.consumer.subscription_prefix, in hex),
                                 which suppliers count as ZeroMQ's XPUB counts subscriptions;
                                 <keep> is `all` for a keep-all consumer (its suppliers then
                                 block rather than drop), `last` for any other

A process's *identity* is `<owner>/<zid>`: the common name of its TLS certificate (the robot
or fleet its key names, `miro keys`; `%` without TLS, and for the router's own session) and
its session id. The owner chunk is what the router's access control matches a certificate's
keys by (transport.zenoh.access: a robot's certificate may declare and reply only under its
own owner chunk, and put events only under its own domain); references carry the identity
(`zenoh/<owner>/<zid>`).

The registry's keys per owner start with the verbatim chunk `@registry`, which no wildcard
matches (not even `**`): a rule of the router's access control that lets a robot query `**`
does not let it query another robot's registry key, so the router's `miro/@registry/ROBOT`
is asked only by ROBOT's certificate (and the fleet's) under `--per-robot`, and the registry
takes the owner chunk of the key a binding operation came on as its caller
(transport.zenoh.registry). Processes reach it at the endpoint `zenoh/naming@<owner>`
(`naming_endpoint`); `zenoh/naming`, the router's call key, serves the registry too, to
everyone (look-ups, listings; binds as well without `--per-robot`).

Names, channels, domains and types become single chunks: `%`, `/`, `*`, `$`, `?`, `#`, `@` are
percent-escaped (Zenoh forbids the others in a chunk, and one that starts with `@` matches no
wildcard; rmw_zenoh escapes `/` too), and an empty
text is `%` alone (a chunk may not be empty; a real `%` is always `%25`).
"""

from __future__ import annotations

from typing import Final
from urllib.parse import unquote

from miro_gen.transport.events.frames import FrameError, topic

PREFIX: Final = "miro"
ENDPOINT_SCHEME: Final = "zenoh/"  # an object reference's endpoint: zenoh/<zid>
NAMING_ENDPOINT: Final = "zenoh/naming"  # the naming registry: the router's session
_OWNED_NAMING: Final = NAMING_ENDPOINT + "@"  # zenoh/naming@<owner>: its key per owner
REGISTRY_KEYS: Final = f"{PREFIX}/@registry/*"  # the registry's queryable of every owner
_ESCAPED: Final = {c: f"%{ord(c):02X}" for c in "%/*$?#@"}  # (`@`: Zenoh's verbatim chunks)
_SPECIAL: Final = frozenset(_ESCAPED)


def escape(text: str) -> str:
    """`text` as one key chunk."""
    if not text:
        return "%"
    if _SPECIAL.isdisjoint(text):
        return text
    return "".join(_ESCAPED.get(c, c) for c in text)


def unescape(chunk: str) -> str:
    """The text of a key chunk (`escape` reversed)."""
    if chunk == "%":
        return ""
    return unquote(chunk) if "%" in chunk else chunk


def identity(owner: str, zid: str) -> str:
    """A process's identity: `<owner>/<zid>` (`owner` its certificate's common name, "" for
    none)."""
    return f"{escape(owner)}/{zid}"


def _identity_of(owner: str, zid: str) -> str | None:
    """`owner/zid` when both are chunks an identity may have, else None."""
    if not owner or _SPECIAL.difference("%").intersection(owner) or not zid.isalnum():
        return None
    return f"{owner}/{zid}"


def zid_part(ident: str) -> str:
    """The session id of an identity."""
    return ident.rsplit("/", 1)[-1]


def owner_part(ident: str) -> str:
    """The owner (a certificate's common name, "" for none) of an identity."""
    return unescape(ident.split("/", 1)[0])


def endpoint(ident: str) -> str:
    """The endpoint references to a process's objects carry (`ident`: its identity)."""
    return ENDPOINT_SCHEME + ident


def zid_of(endpoint_text: str) -> str | None:
    """The identity (`<owner>/<zid>`) an endpoint names (None: not a Zenoh endpoint)."""
    if not endpoint_text.startswith(ENDPOINT_SCHEME):
        return None
    parts = endpoint_text[len(ENDPOINT_SCHEME) :].split("/")
    return _identity_of(*parts) if len(parts) == 2 else None


def call_key(ident: str) -> str:
    return f"{PREFIX}/call/{ident}"


def naming_endpoint(owner: str) -> str:
    """The endpoint a process whose certificate's common name is `owner` binds its names at:
    the registry's key of that owner (`zenoh/naming@<owner>`); without a certificate (`""`)
    the registry's open endpoint, `zenoh/naming`."""
    return f"{_OWNED_NAMING}{escape(owner)}" if owner else NAMING_ENDPOINT


def is_naming(endpoint_text: str) -> bool:
    """Whether an endpoint is the naming registry's (the router's session): `zenoh/naming`,
    or one of its keys per owner (an owner chunk as `escape` makes them)."""
    if endpoint_text == NAMING_ENDPOINT:
        return True
    owner = endpoint_text[len(_OWNED_NAMING) :]
    return (
        endpoint_text.startswith(_OWNED_NAMING)
        and bool(owner)
        and owner != "%"
        and _SPECIAL.difference("%").isdisjoint(owner)
    )


def registry_key(owner: str) -> str:
    """The registry's key for the binding operations of `owner`'s certificate."""
    return f"{PREFIX}/@registry/{escape(owner)}"


def registry_owner(key: str) -> str | None:
    """The owner (a certificate's common name) of a registry key; None for another key."""
    parts = key.split("/")
    if len(parts) != 3 or parts[0] != PREFIX or parts[1] != "@registry" or parts[2] == "%":
        return None
    return unescape(parts[2])


def route_key(endpoint_text: str, ident: str) -> str:
    """The key a call to an object at `endpoint_text` goes to, `ident` the identity of the
    session serving it: the registry's key of an owner (`is_naming` said it is one), or that
    session's call key."""
    if endpoint_text.startswith(_OWNED_NAMING):
        return f"{PREFIX}/@registry/{endpoint_text[len(_OWNED_NAMING) :]}"
    return call_key(ident)


def alive_key(ident: str) -> str:
    return f"{PREFIX}/alive/{ident}"


ALIVE_ALL: Final = f"{PREFIX}/alive/*/*"


def name_token(ident: str, name: str) -> str:
    return f"{PREFIX}/name/{ident}/{escape(name)}"


NAME_TOKENS: Final = f"{PREFIX}/name/*/*/*"


def name_of_token(key: str) -> tuple[str, str] | None:
    """(identity, name) of a name token's key; None for another key."""
    parts = key.split("/")
    if len(parts) != 5 or parts[0] != PREFIX or parts[1] != "name":
        return None
    ident = _identity_of(parts[2], parts[3])
    return None if ident is None else (ident, unescape(parts[4]))


def zid_of_alive(key: str) -> str | None:
    """The identity of a process's liveliness token's key; None for another key."""
    parts = key.split("/")
    if len(parts) != 4 or parts[0] != PREFIX or parts[1] != "alive":
        return None
    return _identity_of(parts[2], parts[3])


def event_key(channel: str, topic_frame: bytes) -> str:
    """The key events of a topic frame (transport.events.frames.topic) travel on."""
    fields = topic_frame.split(b"\0")
    if len(fields) != 3 or fields[2]:
        raise FrameError("malformed topic frame")
    domain, type_name = fields[0].decode(), fields[1].decode()
    return f"{PREFIX}/ev/{escape(channel)}/{escape(domain)}/{escape(type_name)}"


def channel_chunk(channel: str) -> str:
    """The chunk of a channel's keys; for a fleet's channel pattern (`*/EventChannel`: that
    channel of every robot) a chunk with `$*` where the pattern has `*`."""
    if "*" not in channel:
        return escape(channel)
    chunk = "$*".join(escape(part) if part else "" for part in channel.split("*"))
    while "$*$*" in chunk:  # (`**` in a pattern)
        chunk = chunk.replace("$*$*", "$*")
    return "*" if chunk == "$*" else chunk


def is_pattern(channel: str) -> bool:
    return "*" in channel


def sub_channel(key: str) -> str | None:
    """The channel (or channel pattern) of a subscription token's key."""
    parts = key.split("/")
    if len(parts) != 7 or parts[0] != PREFIX or parts[1] != "sub":
        return None
    return unescape(parts[2])


def event_selector(channel: str, prefix: bytes) -> str:
    """The key expression a consumer's subscription prefix (`consumer.subscription_prefix`)
    becomes: the empty prefix any domain and type, `domain\\0` any type of the domain."""
    head = f"{PREFIX}/ev/{channel_chunk(channel)}"
    if not prefix:
        return f"{head}/*/*"
    fields = prefix.split(b"\0")
    domain = escape(fields[0].decode())
    if len(fields) == 2 and not fields[1]:
        return f"{head}/{domain}/*"
    if len(fields) == 3 and not fields[2]:
        return f"{head}/{domain}/{escape(fields[1].decode())}"
    raise FrameError(f"not a subscription prefix: {prefix!r}")


def topic_of(key: str) -> bytes:
    """The topic frame of an event key (`event_key` reversed); FrameError for another key."""
    parts = key.split("/")
    if len(parts) != 5 or parts[0] != PREFIX or parts[1] != "ev":
        raise FrameError(f"not an event key: {key[:200]!r}")
    return topic(unescape(parts[3]), unescape(parts[4]))


KEEP_ALL: Final = "all"  # a subscription token's <keep> chunk: a keep-all consumer's
KEEP_LAST: Final = "last"  # any other consumer's


def sub_token(channel: str, prefix: bytes, zid: str, n: int, *, keep_all: bool = False) -> str:
    """The liveliness token of a consumer's subscription to `prefix` on `channel`."""
    keep = KEEP_ALL if keep_all else KEEP_LAST
    return f"{PREFIX}/sub/{escape(channel)}/{escape(prefix.hex())}/{keep}/{zid}/{n}"


SUB_TOKENS: Final = f"{PREFIX}/sub/*/*/*/*/*"  # every subscription token of every channel


def prefix_of_sub(key: str) -> tuple[bytes, bool]:
    """(the subscription prefix, whether its consumer keeps all) of a token's key; FrameError
    for another key."""
    parts = key.split("/")
    if len(parts) != 7 or parts[0] != PREFIX or parts[1] != "sub":
        raise FrameError(f"not a subscription token: {key[:200]!r}")
    try:
        return bytes.fromhex(unescape(parts[3])), parts[4] == KEEP_ALL
    except ValueError:
        raise FrameError(f"not a subscription token: {key[:200]!r}") from None
