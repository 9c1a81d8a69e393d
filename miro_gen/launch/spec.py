"""Launch files: a robot's services, their order, hosts and restart policies, in TOML.

    [launch]
    context = "robot1"                      # -MNC of every service (default: the host name)
    transport = "zenoh"                     # the backbone (default: zmq; docs/FLEET.md)
    fleet_events = { EventChannel = ["Odometry"] }  # types every robot's channel shares

    [naming]                                # start a naming service (else use a running one)
    channels = ["EventChannel"]

    [services.exampleA]
    run = "exampleA.py"                     # a script or service folder, relative to this file
    restart = "on-failure"

    [services.exampleB]
    run = "exampleB.py"
    after = ["robot1/ExampleA"]             # once this name is bound in the naming service

`read_launch_file` checks everything it can before anything starts, and reports each problem
as `file:line: error: message` (the line of the key at fault). docs/LAUNCH.md is the reference.
"""

from __future__ import annotations

import difflib
import math
import re
import shlex
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from miro_gen.diagnostics import Diagnostic, SourcePos
from miro_gen.launch.locate import KeyLines

RESTART_POLICIES = ("never", "on-failure", "always")
PLACEHOLDERS = ("name", "naming", "context", "dir", "host", "params")
_SERVICE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")
_CONTEXT = re.compile(r"^[^/\s]+(?:/[^/\s]+)*$")
_ANY_PORT = re.compile(r"^tcp://[^:/\s]+:\*$")
_AT_END = " (at end of document)"
_TOML_POSITION = re.compile(r"\s*\(at line (\d+), column (\d+)\)$")

# The range of each number of seconds (finite: TOML also spells nan and inf). The floors keep a
# crash loop slow: a restart waits at least 0.1 s, the back-off grows to at least 1 s, and only
# a run of at least 1 s counts as stable (it ends the series, and so the back-off).
MIN_RESTART_DELAY = 0.1
SECONDS_RANGES = {
    "grace": (0.0, 3600.0),
    "restart_delay": (MIN_RESTART_DELAY, 3600.0),
    "restart_delay_max": (1.0, 3600.0),
    "stable_after": (1.0, 86400.0),
}

_LAUNCH_KEYS = {"context", "naming", "grace", "log_level", "colour", "transport", "fleet_events"}
_RESTART_KEYS = {"restart", "restart_delay", "restart_delay_max", "restart_limit", "stable_after"}
_NAMING_KEYS = {
    "host", "endpoint", "channels", "announce", "insecure", "per_robot", "log_level",
    *_RESTART_KEYS,
}  # fmt: skip
_HOST_KEYS = {"address"}
_SERVICE_KEYS = {
    "run",
    "module",
    "command",
    "args",
    "cwd",
    "host",
    "context",
    "params",
    "parameters",
    "after",
    "ready",
    *_RESTART_KEYS,
    "required",
    "env",
    "log_level",
    "transport",
    "fleet_events",
}


class LaunchError(Exception):
    """The launch file cannot be used; `diagnostics` says where and why (each one line)."""

    def __init__(self, diagnostics: list[Diagnostic]) -> None:
        self.diagnostics = diagnostics
        super().__init__("\n".join(str(d) for d in diagnostics))


@dataclass
class RestartPolicy:
    """When a service that ended is started again, and how patiently.

    `never`, `on-failure` (a non-zero exit or a signal) or `always`; the first restart waits
    `delay` seconds, each consecutive one twice as long up to `delay_max`; after `limit`
    consecutive restarts (None: no limit) the service is given up. A run that lasted
    `stable_after` seconds ends the series: the next failure starts again from `delay`."""

    when: str = "on-failure"
    delay: float = 0.5
    delay_max: float = 10.0
    limit: int | None = 5
    stable_after: float = 10.0

    def wants_restart(self, code: int) -> bool:
        return self.when == "always" or (self.when == "on-failure" and code != 0)

    def backoff(self, consecutive: int) -> float:
        """The wait before restart number `consecutive` (1-based) of a series."""
        return float(min(self.delay * 2 ** max(consecutive - 1, 0), self.delay_max))


@dataclass
class ServiceSpec:
    """One service of a launch file: what to run and how to look after it."""

    name: str
    argv: list[str]  # the program and its own arguments (placeholders filled in at start)
    python: bool  # a service on miro-gen's runtime: it gets the common options
    cwd: Path
    line: int
    host: str | None = None
    context: str | None = None
    params_file: Path | None = None
    parameters: dict[str, Any] = field(default_factory=dict)  # SECTION -> CATEGORY -> values
    after: list[str] = field(default_factory=list)  # services of the file, or bound names
    ready: str | None = None  # a line of output that says it is ready
    restart: RestartPolicy = field(default_factory=RestartPolicy)
    required: bool = True
    env: dict[str, str] = field(default_factory=dict)
    log_level: int | None = None
    transport: str | None = None  # zmq or zenoh (MIRO_TRANSPORT); None: the environment's
    fleet_events: dict[str, frozenset[str]] | None = None  # MIRO_FLEET_EVENTS; None: as is


@dataclass
class NamingSpec:
    """The naming service the launch starts (`miro naming`), with the channels it hosts."""

    endpoint: str
    line: int
    host: str | None = None
    channels: list[str] = field(default_factory=list)
    announce: bool = True
    insecure: bool = False  # beyond loopback without a key (Zenoh's router: docs/FLEET.md)
    per_robot: list[str] = field(default_factory=list)  # Zenoh: each robot only its own keys
    restart: RestartPolicy = field(default_factory=lambda: RestartPolicy("always", limit=None))
    log_level: int | None = None


@dataclass
class LaunchSpec:
    path: Path
    services: list[ServiceSpec]
    naming: NamingSpec | None = None
    naming_url: str | None = None  # where services find the naming service, when given
    context: str | None = None
    grace: float = 5.0
    log_level: int | None = None
    colour: str = "auto"
    transport: str | None = None  # [launch] transport: the services' and the naming service's
    fleet_events: dict[str, frozenset[str]] | None = None  # [launch] fleet_events
    hosts: dict[str, str | None] = field(default_factory=dict)  # name -> address to advertise
    lines: KeyLines | None = None

    @property
    def folder(self) -> Path:
        return self.path.parent

    def service(self, name: str) -> ServiceSpec | None:
        return next((s for s in self.services if s.name == name), None)

    def error(self, message: str, *path: str | int) -> Diagnostic:
        line = self.lines.line(*path) if self.lines is not None else 1
        return Diagnostic("error", SourcePos(str(self.path), line, 0), message)


class _Reader:
    """Checks the parsed document, collecting every problem with its line."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines = KeyLines(text)
        self.problems: list[Diagnostic] = []

    def error(self, message: str, *where: str | int) -> None:
        pos = SourcePos(str(self.path), self.lines.line(*where), 0)
        self.problems.append(Diagnostic("error", pos, message))

    def table(self, value: Any, *where: str) -> dict[str, Any]:
        if isinstance(value, dict):
            return value
        self.error(f"{'.'.join(where)} must be a table", *where)
        return {}

    def keys(self, table: dict[str, Any], allowed: set[str], *where: str) -> None:
        for key in table:
            if key not in allowed:
                close = difflib.get_close_matches(key, sorted(allowed), 1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                place = f"[{'.'.join(where)}]" if where else "the file"
                self.error(f"unknown key {key!r} in {place}{hint}", *where, key)

    def typed(self, table: dict[str, Any], key: str, kinds: Any, what: str, *where: str) -> Any:
        value = table.get(key)
        if value is None:
            return None
        allowed = kinds if isinstance(kinds, tuple) else (kinds,)
        if not isinstance(value, allowed) or (isinstance(value, bool) and bool not in allowed):
            self.error(f"{key} must be {what}, not {value!r}", *where, key)
            return None
        return value

    def seconds(self, table: dict[str, Any], key: str, *where: str) -> float | None:
        """`key`'s number of seconds, finite and within SECONDS_RANGES[key]."""
        value = self.typed(table, key, (int, float), "a number of seconds", *where)
        if value is None:
            return None
        low, high = SECONDS_RANGES[key]
        if not (math.isfinite(value) and low <= value <= high):
            self.error(f"{key} must be from {low:g} to {high:g} seconds, not {value}", *where, key)
            return None
        return float(value)

    def level(self, table: dict[str, Any], *where: str) -> int | None:
        value = self.typed(table, "log_level", int, "a log level from 0 to 9", *where)
        if value is not None and not 0 <= value <= 9:
            self.error(f"log_level must be from 0 to 9, not {value}", *where, "log_level")
            return None
        return value  # type: ignore[no-any-return]

    def strings(self, table: dict[str, Any], key: str, *where: str) -> list[str]:
        value = table.get(key)
        if value is None:
            return []
        if isinstance(value, str):
            return [value]
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            return list(value)
        self.error(f"{key} must be a string or a list of strings", *where, key)
        return []

    def policy(self, table: dict[str, Any], default: RestartPolicy, *where: str) -> RestartPolicy:
        p = RestartPolicy(**default.__dict__)
        when = self.typed(table, "restart", str, "never, on-failure or always", *where)
        if when is not None:
            if when not in RESTART_POLICIES:
                close = difflib.get_close_matches(when, RESTART_POLICIES, 1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                self.error(
                    f"restart must be never, on-failure or always, not {when!r}{hint}",
                    *where,
                    "restart",
                )
            else:
                p.when = when
        for key, attr in (
            ("restart_delay", "delay"),
            ("restart_delay_max", "delay_max"),
            ("stable_after", "stable_after"),
        ):
            seconds = self.seconds(table, key, *where)
            if seconds is not None:
                setattr(p, attr, seconds)
        if "restart_limit" in table:
            limit = table["restart_limit"]
            if isinstance(limit, bool) or not isinstance(limit, int) or limit < 0:
                self.error(
                    f"restart_limit must be a number of restarts (0 or more), not {limit!r}",
                    *where,
                    "restart_limit",
                )
            else:
                p.limit = limit
        if p.delay_max < p.delay:
            p.delay_max = p.delay
        return p


def read_launch_file(path: str | Path) -> LaunchSpec:
    """The launch file at `path`, checked; LaunchError listing every problem otherwise."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        raise LaunchError([Diagnostic("error", SourcePos(str(path), 0, 0), reason)]) from None
    return parse_launch_text(text, path)


def parse_launch_text(text: str, path: Path) -> LaunchSpec:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        message = str(e)
        m = _TOML_POSITION.search(message)
        line, col = (int(m.group(1)), int(m.group(2))) if m else (1, 0)
        if message.endswith(_AT_END):
            line, col = max(len(text.splitlines()), 1), 0
            message = message[: -len(_AT_END)] + " (at the end of the file)"
        message = _TOML_POSITION.sub("", message)
        raise LaunchError([Diagnostic("error", SourcePos(str(path), line, col), message)]) from None
    r = _Reader(path, text)
    r.keys(doc, {"launch", "naming", "hosts", "services"})
    spec = LaunchSpec(path=path.resolve(), services=[], lines=r.lines)
    launch = r.table(doc.get("launch", {}), "launch")
    r.keys(launch, _LAUNCH_KEYS, "launch")
    spec.context = _context(r, launch, "launch")
    url = r.typed(launch, "naming", str, "a naming service address (tcp://HOST:PORT)", "launch")
    if url is not None:
        spec.naming_url = _naming_url(r, url, "launch", "naming")
    grace = r.seconds(launch, "grace", "launch")
    if grace is not None:
        spec.grace = grace
    spec.log_level = r.level(launch, "launch")
    spec.transport = _transport(r, launch, "launch")
    spec.fleet_events = _fleet_events(r, launch, "launch")
    colour = r.typed(launch, "colour", str, "auto, always or never", "launch")
    if colour is not None:
        if colour not in ("auto", "always", "never"):
            r.error(f"colour must be auto, always or never, not {colour!r}", "launch", "colour")
        else:
            spec.colour = colour
    hosts = r.table(doc.get("hosts", {}), "hosts")
    for name, table in hosts.items():
        table = r.table(table, "hosts", name)
        r.keys(table, _HOST_KEYS, "hosts", name)
        spec.hosts[name] = r.typed(table, "address", str, "an address", "hosts", name)
    if "naming" in doc:
        spec.naming = _naming(r, r.table(doc["naming"], "naming"), spec)
    services = r.table(doc.get("services", {}), "services")
    if not services:
        r.error("the file declares no services ([services.NAME] tables)", "services")
    for name, table in services.items():
        service = _service(r, name, r.table(table, "services", name), spec)
        if service is not None:
            spec.services.append(service)
    _check_order(r, spec)
    if r.problems:
        raise LaunchError(r.problems)
    return spec


def _context(r: _Reader, table: dict[str, Any], *where: str) -> str | None:
    context = r.typed(table, "context", str, "a naming context (robot1, lab/robot1)", *where)
    if context is not None and not _CONTEXT.match(context):
        r.error(f"{context!r} is not a naming context (robot1, lab/robot1)", *where, "context")
        return None
    return context  # type: ignore[no-any-return]


def _transport(r: _Reader, table: dict[str, Any], *where: str) -> str | None:
    """The backbone a table names (zmq or zenoh; docs/FLEET.md), if it names one."""
    from miro_gen.service.options import TRANSPORTS

    value = r.typed(table, "transport", str, " or ".join(TRANSPORTS), *where)
    if value is not None and value not in TRANSPORTS:
        close = difflib.get_close_matches(value, TRANSPORTS, 1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        r.error(
            f"transport must be {' or '.join(TRANSPORTS)}, not {value!r}{hint}",
            *where,
            "transport",
        )
        return None
    return value  # type: ignore[no-any-return]


def _fleet_events(
    r: _Reader, table: dict[str, Any], *where: str
) -> dict[str, frozenset[str]] | None:
    """`fleet_events = { CHANNEL = ["TYPE", ...] }`: the event types each channel (by its name
    without context) shares with every robot over Zenoh (transport.zenoh.fleet)."""
    from miro_gen.transport.usage import UsageError
    from miro_gen.transport.zenoh.fleet import check_name

    if "fleet_events" not in table:
        return None
    shared: dict[str, frozenset[str]] = {}
    for channel, types in r.table(table["fleet_events"], *where, "fleet_events").items():
        place = (*where, "fleet_events", channel)
        names = [types] if isinstance(types, str) else types
        if not isinstance(names, list) or not all(isinstance(t, str) for t in names):
            r.error(f"fleet_events.{channel} must be a list of event types", *place)
            continue
        if not names:
            r.error(f'fleet_events.{channel} must name event types (or ["*"])', *place)
            continue
        try:
            shared[check_name(channel, "channel")] = frozenset(check_name(t, "type") for t in names)
        except UsageError as e:
            r.error(f"fleet_events: {e}", *place)
    return shared


def _naming_url(r: _Reader, text: str, *where: str) -> str | None:
    from miro_gen.service.options import UsageError, naming_endpoint

    try:
        return naming_endpoint(text)
    except UsageError as e:
        r.error(str(e), *where)
        return None


def _host(r: _Reader, table: dict[str, Any], spec: LaunchSpec, *where: str) -> str | None:
    host = r.typed(table, "host", str, "the name of a host", *where)
    if host is not None and spec.hosts and host not in spec.hosts:
        close = difflib.get_close_matches(host, sorted(spec.hosts), 1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        r.error(f"host {host!r} is not declared in [hosts]{hint}", *where, "host")
    return host  # type: ignore[no-any-return]


def _naming(r: _Reader, table: dict[str, Any], spec: LaunchSpec) -> NamingSpec:
    r.keys(table, _NAMING_KEYS, "naming")
    endpoint = r.typed(table, "endpoint", str, "an endpoint (tcp://HOST:PORT)", "naming")
    if endpoint is not None and not _ANY_PORT.match(endpoint):  # a free port: told at start
        endpoint = _naming_url(r, endpoint, "naming", "endpoint")
    naming = NamingSpec(
        endpoint=endpoint or spec.naming_url or _default_naming(), line=r.lines.line("naming")
    )
    naming.host = _host(r, table, spec, "naming")
    naming.channels = r.strings(table, "channels", "naming")
    naming.per_robot = r.strings(table, "per_robot", "naming")
    announce = r.typed(table, "announce", bool, "true or false", "naming")
    if announce is not None:
        naming.announce = announce
    insecure = r.typed(table, "insecure", bool, "true or false", "naming")
    if insecure is not None:
        naming.insecure = insecure
    naming.restart = r.policy(table, naming.restart, "naming")
    naming.log_level = r.level(table, "naming")
    return naming


def _default_naming() -> str:
    """Where `miro naming` serves by default: $MIRO_NAMING, else tcp://127.0.0.1:2809."""
    import os

    from miro_gen.service.options import DEFAULT_NAMING, UsageError, naming_endpoint

    try:
        return naming_endpoint(os.environ.get("MIRO_NAMING") or DEFAULT_NAMING)
    except UsageError:
        return DEFAULT_NAMING


def _service(r: _Reader, name: str, table: dict[str, Any], spec: LaunchSpec) -> ServiceSpec | None:
    where = ("services", name)
    if not _SERVICE_NAME.match(name):
        r.error(
            f"{name!r} is not a service name (letters, digits, _ . -; not starting with a digit)",
            *where,
        )
    r.keys(table, _SERVICE_KEYS, *where)
    kinds = [k for k in ("run", "module", "command") if k in table]
    if len(kinds) != 1:
        what = "none" if not kinds else " and ".join(kinds)
        r.error(f"[services.{name}] needs exactly one of run, module or command ({what})", *where)
        return None
    base = spec.folder
    cwd_text = r.typed(table, "cwd", str, "a folder", *where)
    cwd = (base / cwd_text) if cwd_text else None
    python = True
    argv: list[str]
    if "run" in table:
        target = r.typed(table, "run", str, "a script or service folder", *where)
        if target is None:
            return None
        script = (base / target).resolve()
        if script.is_dir() and not (script / "__main__.py").is_file():
            r.error(f"{target} is a folder without __main__.py", *where, "run")
        elif not script.exists():
            r.error(f"{target}: no such script or service folder", *where, "run")
        if script.is_file() and script.suffix != ".py":
            python = False  # a program of another kind (a C++ service)
            argv = [str(script)]
        else:
            argv = [sys.executable, "-u", str(script)]
    elif "module" in table:
        module = r.typed(table, "module", str, "a module name", *where)
        if module is None:
            return None
        argv = [sys.executable, "-u", "-m", module]
        cwd = cwd or project_root(base)
    else:
        python = False
        command = table["command"]
        if isinstance(command, str):
            try:
                argv = shlex.split(command)
            except ValueError as e:
                r.error(f"command: {e}", *where, "command")
                return None
        elif isinstance(command, list) and all(isinstance(c, str) for c in command):
            argv = list(command)
        else:
            r.error("command must be a string or a list of strings", *where, "command")
            return None
        if not argv:
            r.error("command is empty", *where, "command")
            return None
        if argv[0] == "miro":  # this installation's miro, whatever PATH says
            argv = [sys.executable, "-u", "-m", "miro_gen.cli.main", *argv[1:]]
    args = table.get("args", [])
    if not (isinstance(args, list) and all(isinstance(a, str | int | float) for a in args)):
        r.error("args must be a list of strings", *where, "args")
        args = []
    argv += [str(a) for a in args]
    for word in argv:
        for m in re.finditer(r"(?<!\{)\{([^{}]*)\}(?!\})", word):
            if m.group(1) not in PLACEHOLDERS:
                r.error(
                    f"unknown placeholder {{{m.group(1)}}} (known: "
                    + ", ".join(f"{{{p}}}" for p in PLACEHOLDERS)
                    + "; write {{ and }} for braces)",
                    *where,
                    "args" if "args" in table else kinds[0],
                )
    service = ServiceSpec(
        name=name, argv=argv, python=python, cwd=cwd or base, line=r.lines.line(*where)
    )
    service.host = _host(r, table, spec, *where)
    service.context = _context(r, table, *where) or spec.context
    params = r.typed(table, "params", str, "a run-time parameter document (-MCF)", *where)
    if params is not None:
        service.params_file = (base / params).resolve()
        if not service.params_file.is_file():
            r.error(f"{params}: no such parameter document", *where, "params")
    if "parameters" in table:
        service.parameters = _parameters(r, table["parameters"], *where, "parameters")
    service.after = r.strings(table, "after", *where)
    service.ready = r.typed(table, "ready", str, "a line of output to wait for", *where)
    service.restart = r.policy(table, service.restart, *where)
    required = r.typed(table, "required", bool, "true or false", *where)
    if required is not None:
        service.required = required
    env = r.table(table.get("env", {}), *where, "env")
    for key, value in env.items():
        if isinstance(value, bool) or not isinstance(value, str | int | float):
            r.error(f"env.{key} must be a string", *where, "env", key)
        else:
            service.env[key] = str(value)
    service.log_level = r.level(table, *where)
    if service.log_level is None:
        service.log_level = spec.log_level
    own = _transport(r, table, *where)
    service.transport = own or spec.transport
    service.fleet_events = _fleet_events(r, table, *where)
    if service.fleet_events is None:
        service.fleet_events = spec.fleet_events
    if spec.naming is not None and own is not None and own != (spec.transport or "zmq"):
        r.error(
            f"transport {own!r} is not the backbone of the naming service this "
            f"file starts ({spec.transport or 'zmq'}: [launch] transport)",
            *where,
            "transport",
        )
    return service


def _parameters(r: _Reader, value: Any, *where: str) -> dict[str, Any]:
    """`parameters.SECTION.CATEGORY` tables: run-time parameter values, as a document has."""
    sections = r.table(value, *where)
    for section, categories in sections.items():
        categories = r.table(categories, *where, section)
        for category, values in categories.items():
            if not isinstance(values, dict):
                r.error(
                    f"parameters.{section}.{category} must be a table of parameter values "
                    f"(parameters.SECTION.CATEGORY.NAME = VALUE)",
                    *where,
                    section,
                    category,
                )
    return sections


def _check_order(r: _Reader, spec: LaunchSpec) -> None:
    """Dependencies on services of the file must not go round in circles."""
    names = {s.name for s in spec.services}
    graph = {s.name: [a for a in s.after if a in names] for s in spec.services}
    for s in spec.services:
        if s.name in s.after:
            r.error(f"{s.name} cannot start after itself", "services", s.name, "after")
    state: dict[str, int] = {}

    def visit(name: str, trail: list[str]) -> None:
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            cycle = [*trail[trail.index(name) :], name]
            r.error(
                "the services wait for each other in a circle: " + " -> ".join(cycle),
                "services",
                name,
                "after",
            )
            return
        state[name] = 1
        for dep in graph[name]:
            if dep != name:
                visit(dep, [*trail, name])
        state[name] = 2

    for s in spec.services:
        visit(s.name, [])


def project_root(folder: Path) -> Path:
    """The project a launch file belongs to: the nearest folder (from its own up) with
    `generated/` or `pyproject.toml`; its own folder when there is none."""
    for candidate in (folder, *folder.parents):
        if (candidate / "generated").is_dir() or (candidate / "pyproject.toml").is_file():
            return candidate
    return folder
