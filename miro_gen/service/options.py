"""The options every Miro service accepts, removed from `argv` before the service sees the rest.

As in Miro, a service's `main(argc, argv)` hands its arguments to the middleware first, which
takes what it knows and leaves the service's own ones. The contract (DESIGN.md, "Command line"):

* `--naming URL` (env `MIRO_NAMING`), or the manual's `-ORBInitRef NameService=URL` (env
  `NameServiceIOR`): where the naming service is; default `tcp://127.0.0.1:2809`. `tcp://` is
  `miro naming` (ZeroMQ); `IOR:...` a CORBA naming service; `corbaloc:iiop:HOST:PORT/...`,
  `iioploc://HOST:PORT/...` and `corbaname:...` whichever of the two answers there
  (`miro_gen.corba.naming.decide`, docs/CORBA.md);
* `--iiop-endpoint HOST:PORT` or `-ORBEndpoint iiop://HOST:PORT` (TAO's spelling; omniORB's
  `-ORBendPoint giop:tcp:HOST:PORT` too): where a server listens for IIOP (a fixed port keeps
  its IORs valid across restarts);
* other `-ORB*` options (TAO's) are accepted and ignored, with a one-line notice each;
* `-MNC NAME` / `-MiroNamingContext NAME`: the naming context, default the host name;
* `-MLL N` / `-MiroLogLevel N`: Miro's log level, 0 emergency ... 4 warning (default) ... 9 prattle;
* `-MLF CAT [CAT ...]` / `-MiroLogFilter CAT [CAT ...]`: the log categories to show (default all);
* `-MCF FILE` / `-MiroConfigFile FILE`: the run-time parameter document;
* `--host HOST` (env `MIRO_HOST`): the address other machines reach this process at; by default
  the one towards the naming service (see `miro_gen.transport.addresses`, docs/PROTOCOL.md);
* `--bind ADDR|IFACE` (env `MIRO_BIND`): the interface a server listens on instead of every
  interface (`0.0.0.0`) when other hosts must reach it;
* `--keys FILE` (env `MIRO_KEYS`): the robot's or fleet's key (`miro keys new`): CURVE on
  ZeroMQ, mutual TLS on Zenoh (transport.zenoh.security); `--insecure`: neither, even beyond
  loopback (docs/SECURITY.md);
* `--transport zmq|zenoh` (env `MIRO_TRANSPORT`): the backbone (docs/FLEET.md);
* `--max-message-size BYTES` (env `MIRO_MAX_MESSAGE_SIZE`; suffixes K, M, G): the largest
  message a socket accepts (default 8M, like omniORB's `giopMaxMsgSize`);
* `--wait-naming SECONDS` (env `MIRO_WAIT_NAMING`): how long a server waits for a naming
  service that does not answer yet before it gives up (default: as long as it takes, saying
  so once; `0` gives up at once, for scripts);
* `--clock wall|log|log:CHANNEL`: the time `miro_gen.clock.now()` and reactor timers follow:
  wall time (default), or the clock of a log player (`miro log play`), published on the
  channel `LogClock` (or CHANNEL); see docs/LOGS.md.

Options may also be written `--naming=URL`. A missing or malformed value raises `UsageError`
with a message naming the option.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from miro_gen.transport.usage import UsageError as UsageError  # (its users look here)

DEFAULT_NAMING = "tcp://127.0.0.1:2809"
DEFAULT_LOG_LEVEL = 4

# iioploc://HOST:PORT/NameService, corbaloc:iiop:HOST:PORT/NameService (also corbaloc::HOST:PORT,
# iiop versions like 1.2@HOST), optionally after "NameService=".
_CORBALOC = re.compile(
    r"^(?:NameService=)?(?:iioploc://|corbaloc:(?:iiop)?:)(?:\d+\.\d+@)?"
    r"(?P<host>\[[^\]]+\]|[^:/\[\]]+)(?::(?P<port>\d+))?(?:/.*)?$"
)
_TCP = re.compile(r"^tcp://(?P<host>\[[^\]]+\]|[^:/\[\]]+):(?P<port>\d+)$")
_IIOP_DEFAULT_PORT = 2809  # the port corbaloc implies when none is given


@dataclass
class CommonOptions:
    """What the common options say (the defaults when absent)."""

    naming: str = DEFAULT_NAMING
    naming_given: bool = False  # by an option or the environment (else: the default, or found)
    naming_context: str = field(default_factory=socket.gethostname)
    log_level: int = DEFAULT_LOG_LEVEL
    log_filter: list[str] = field(default_factory=list)  # empty: every category
    config_file: str | None = None
    host: str | None = None
    clock: str = "wall"  # or "log" (the channel LogClock), or "log:CHANNEL"
    bind: str | None = None  # --bind: the interface to listen on
    keys: str | None = None  # --keys: the CURVE key file
    insecure: bool = False  # --insecure: no CURVE, whatever is bound
    max_message_size: int | None = None  # --max-message-size, bytes
    naming_url: str | None = None  # the naming service's CORBA URL, when one was given
    iiop_endpoint: str | None = None  # HOST:PORT to serve IIOP on (--iiop-endpoint)
    wait_naming: float | None = None  # --wait-naming: seconds a server waits (None: no limit)
    ignored: list[str] = field(default_factory=list)  # -ORB options given, for the notice
    transport: str = "zmq"  # --transport / MIRO_TRANSPORT: the backbone, zmq or zenoh


def naming_endpoint(text: str) -> str:
    """`tcp://HOST:PORT` for a naming-service address in any of the accepted spellings."""
    text = text.strip()
    m = _TCP.match(text)
    if m:
        return text
    m = _CORBALOC.match(text)
    if m:
        port = m.group("port") or str(_IIOP_DEFAULT_PORT)
        return f"tcp://{m.group('host')}:{port}"
    address = _corba_address(text)
    if address is not None:
        return address
    raise UsageError(
        f"cannot read the naming service address {text!r}: expected tcp://HOST:PORT, "
        "iioploc://HOST:PORT/NameService, corbaloc:iiop:HOST:PORT/NameService, "
        "corbaname:iiop:HOST:PORT or IOR:..."
    )


def _corba_address(text: str) -> str | None:
    """`tcp://HOST:PORT` of the first IIOP address of an IOR or corbaname URL."""
    from miro_gen.corba.ior import CorbaName, UrlError, parse_url

    try:
        parsed = parse_url(text.removeprefix("NameService="))
    except UrlError:
        return None
    ior = parsed.context if isinstance(parsed, CorbaName) else parsed
    profile = ior.iiop_profile()
    if profile is None:
        return None
    host = f"[{profile.host}]" if ":" in profile.host else profile.host
    return f"tcp://{host}:{profile.port}"


def _naming(opts: CommonOptions, text: str) -> None:
    """Set where the naming service is (and, for a CORBA URL, the URL itself)."""
    opts.naming = naming_endpoint(text)
    opts.naming_given = True
    bare = text.strip().removeprefix("NameService=")
    opts.naming_url = None if bare.startswith("tcp://") else bare


def iiop_endpoint(text: str, option: str) -> str:
    """HOST:PORT (HOST may be empty: every interface) of an IIOP endpoint option."""
    t = text.strip()
    for prefix in ("iiop://", "giop:tcp:", "iiop:"):
        if t.startswith(prefix):
            t = t[len(prefix) :]
    t = t.split("/")[0].removeprefix("1.2@").removeprefix("1.1@").removeprefix("1.0@")
    host, sep, port = t.rpartition(":")
    if not sep:
        host, port = t, "0"
    if not port.isdigit() or int(port) > 65535:
        raise UsageError(f"{option} takes HOST:PORT (iiop://HOST:PORT), not {text!r}")
    return f"{host}:{int(port or 0)}"


def parse_common_options(
    argv: Sequence[str], environ: Mapping[str, str] | None = None
) -> tuple[CommonOptions, list[str]]:
    """The common options in `argv` (program name excluded), and the arguments left over."""
    env = os.environ if environ is None else environ
    opts = CommonOptions()
    if env.get("NameServiceIOR"):
        _naming(opts, env["NameServiceIOR"])
    if env.get("MIRO_NAMING"):
        _naming(opts, env["MIRO_NAMING"])
    if env.get("MIRO_HOST"):
        opts.host = env["MIRO_HOST"]
    opts.bind = env.get("MIRO_BIND") or None
    opts.keys = env.get("MIRO_KEYS") or None
    if env.get("MIRO_MAX_MESSAGE_SIZE"):
        opts.max_message_size = byte_size(env["MIRO_MAX_MESSAGE_SIZE"], "MIRO_MAX_MESSAGE_SIZE")
    if env.get("MIRO_WAIT_NAMING"):
        opts.wait_naming = seconds(env["MIRO_WAIT_NAMING"], "MIRO_WAIT_NAMING")
    if env.get("MIRO_TRANSPORT"):
        opts.transport = transport(env["MIRO_TRANSPORT"], "MIRO_TRANSPORT")
    rest: list[str] = []
    args = list(argv)
    i = 0

    def value(name: str) -> str:
        nonlocal i
        if i + 1 >= len(args):
            raise UsageError(f"{name} needs a value")
        i += 1
        return args[i]

    while i < len(args):
        arg = args[i]
        name, eq, inline = arg.partition("=") if arg.startswith("--") else (arg, "", "")
        if name == "--":  # everything after belongs to the service
            rest += args[i:]
            break
        if name == "--clock":
            opts.clock = _clock(inline if eq else value(name))
        elif name == "--transport":
            opts.transport = transport(inline if eq else value(name), name)
        elif name in ("--bind", "--keys", "--max-message-size", "--wait-naming"):
            text = inline if eq else value(name)
            if name == "--wait-naming":
                opts.wait_naming = seconds(text, name)
            elif name == "--bind":
                opts.bind = text
            elif name == "--keys":
                opts.keys = text
            else:
                opts.max_message_size = byte_size(text, name)
        elif arg == "--insecure":
            opts.insecure = True
        elif name == "--iiop-endpoint" or arg in ("-ORBEndpoint", "-ORBendPoint"):
            text = inline if eq else value(arg if arg.startswith("-ORB") else name)
            opts.iiop_endpoint = iiop_endpoint(text, name)
        elif name in ("--naming", "--host") or arg in ("-MNC", "-MiroNamingContext", "-MCF"):
            text = inline if eq else value(name)
            if name == "--naming":
                _naming(opts, text)
            elif name == "--host":
                opts.host = text
            elif name == "-MCF":
                opts.config_file = text
            else:
                opts.naming_context = _context(text)
        elif arg == "-MiroConfigFile":
            opts.config_file = value(arg)
        elif arg in ("-MLL", "-MiroLogLevel"):
            opts.log_level = _level(value(arg), arg)
        elif arg in ("-MLF", "-MiroLogFilter"):
            cats = []
            while i + 1 < len(args) and not args[i + 1].startswith("-"):
                i += 1
                cats.append(args[i])
            if not cats:
                raise UsageError(f"{arg} needs at least one category (such as MIRO)")
            opts.log_filter += cats
        elif arg == "-ORBInitRef":
            ref = value(arg)
            if ref.startswith("NameService="):
                _naming(opts, ref)
            else:
                opts.ignored.append(f"{arg} {ref}")
        elif arg.startswith("-ORB"):
            # TAO's options take one value, except the few written -ORBOption=value.
            if "=" not in arg and i + 1 < len(args) and not args[i + 1].startswith("-"):
                opts.ignored.append(f"{arg} {value(arg)}")
            else:
                opts.ignored.append(arg)
        else:
            rest.append(arg)
        i += 1
    return opts, rest


TRANSPORTS = ("zmq", "zenoh")


def transport(text: str, option: str) -> str:
    """The backbone an option names: zmq (the default) or zenoh (docs/FLEET.md)."""
    t = text.strip().lower()
    if t not in TRANSPORTS:
        raise UsageError(f"{option}: unknown transport {text!r} (expected zmq or zenoh)")
    return t


def byte_size(text: str, option: str) -> int:
    """A number of bytes: `8388608`, `8M`, `512K`, `1G` (powers of 1024)."""
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(t[-1:], 1)
    try:
        n = int(t[:-1] if scale > 1 else t) * scale
    except ValueError:
        n = 0
    if not 1024 <= n <= 1 << 31:
        raise UsageError(f"{option} takes a size from 1K to 2G (such as 8M), not {text!r}")
    return n


def seconds(text: str, option: str) -> float:
    """A number of seconds, 0 or more (finite)."""
    try:
        n = float(text)
    except ValueError:
        n = -1.0
    if not 0 <= n < float("inf"):
        raise UsageError(f"{option} takes a number of seconds, 0 or more, not {text!r}")
    return n


def _clock(text: str) -> str:
    kind, sep, channel = text.partition(":")
    if text == "wall" or (kind == "log" and (not sep or channel.strip("/"))):
        return text
    raise UsageError(f"--clock takes wall, log or log:CHANNEL, not {text!r}")


def _level(text: str, option: str) -> int:
    try:
        level = int(text)
    except ValueError:
        raise UsageError(f"{option} takes a level from 0 to 9, not {text!r}") from None
    if not 0 <= level <= 9:
        raise UsageError(f"{option} takes a level from 0 to 9, not {level}")
    return level


def _context(text: str) -> str:
    parts = [p for p in text.split("/") if p]
    if not parts:
        raise UsageError(f"the naming context {text!r} is empty")
    return "/".join(parts)


COMMON_HELP = (
    ("--naming URL", "where the naming service is: tcp://HOST:PORT (env MIRO_NAMING; default "
     f"{DEFAULT_NAMING}), or a CORBA one: IOR:..., corbaloc:iiop:HOST:PORT/NameService"),
    ("-ORBInitRef NameService=iioploc://HOST:PORT/NameService", "the same, as Miro wrote it"),
    ("--iiop-endpoint HOST:PORT", "where to serve IIOP (-ORBEndpoint iiop://HOST:PORT)"),
    ("-MNC NAME", "naming context (-MiroNamingContext; default: the host name)"),
    ("-MLL N", "log level, 0 emergency ... 4 warning (default) ... 9 prattle (-MiroLogLevel)"),
    ("-MLF CAT [CAT ...]", "log categories to show (-MiroLogFilter; default: all)"),
    ("-MCF FILE", "run-time parameter document (-MiroConfigFile; default: <hostname>.xml)"),
    ("--host ADDR", "the address other machines reach this process at (env MIRO_HOST)"),
    ("--wait-naming SECONDS", "how long a server waits for its naming service to answer "
     "(env MIRO_WAIT_NAMING; default: until it does)"),
    ("--clock wall|log|log:CHANNEL", "run on wall time (default) or a log player's time"),
    ("--transport zmq|zenoh", "the backbone: ZeroMQ (default) or Zenoh, whose router "
     "`miro naming --zenoh` hosts at --naming (env MIRO_TRANSPORT)"),
    ("--keys FILE", "the robot's or fleet's key (`miro keys new`; env MIRO_KEYS; default "
     "~/.config/miro/fleet.key_secret when it exists): CURVE on ZeroMQ, mutual TLS on Zenoh; "
     "needed beyond loopback"),
    ("--insecure", "beyond loopback without a key: in the clear, open to anyone who can "
     "connect (docs/SECURITY.md)"),
)  # fmt: skip


def service_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """An argument parser for a service's own options, parsing what `Server(argv)` or
    `Client(argv)` left in `argv` (`parser.parse_args(server.argv[1:])`): --help works, an
    unknown option is an error (status 2), and the help lists the common options too."""
    lines = [f"  {flag}\n      {text}" for flag, text in COMMON_HELP]
    return argparse.ArgumentParser(
        prog=prog,
        description=description,
        epilog="common options (every service takes them):\n" + "\n".join(lines),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
