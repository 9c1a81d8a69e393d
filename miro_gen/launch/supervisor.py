"""Starting a robot's services in order, keeping them up, and stopping them all.

A `Supervisor` runs one host's part of a launch file. Each service waits until the naming service
answers and what it is declared to start after is there (another service of the file up, or a
name bound in the naming service); it then runs as a process of its own, in its own process
group, its output copied line by line to the console with its name in front. A service that ends
is started again as its restart policy says, after a back-off that doubles with each consecutive
restart; when a required service cannot stay up (its policy says no more, or its limit is
reached) everything is stopped and the launch ends with status 1. `stop()` (Ctrl-C) stops the
services in waves, those that depend on others first and the naming service last: SIGTERM to
each process group, SIGKILL to what is left after the grace period, so that nothing is left
behind. The groups are owned through a `ProcessTree` (launch.tree), whose watcher process
stops them in the same way when the launch itself is killed.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from miro_gen.launch.console import Console, Row, since
from miro_gen.launch.documents import write_parameters
from miro_gen.launch.names import NameWatcher
from miro_gen.launch.spec import LaunchSpec, RestartPolicy, ServiceSpec, project_root
from miro_gen.launch.tree import ProcessTree, kill, left, send

NAMING_LABEL = "naming"
NAMING_READY = "naming service at"
POLL = 0.1  # seconds between looks at the children when nothing wakes the loop


class PlanError(Exception):
    """This host's part of the launch file cannot be started as it is (one line)."""


@dataclass
class Part:
    """What one host starts: its services (the naming service first, when it runs here) and
    where they find the naming service."""

    host: str | None
    services: list[ServiceSpec]
    naming_url: str | None  # None: the services' own default (MIRO_NAMING, or 127.0.0.1:2809)
    others: dict[str, str]  # services of the file that run on other hosts -> their host
    discover: bool = False  # find the naming service by its announcement (multicast DNS)


def backbone(spec: LaunchSpec) -> str:
    """The file's backbone: its `[launch] transport`, else the environment's (MIRO_TRANSPORT),
    else ZeroMQ. The naming service it starts, and the watch on names, are that backbone's."""
    chosen = spec.transport or os.environ.get("MIRO_TRANSPORT", "").strip().lower()
    return "zenoh" if chosen == "zenoh" else "zmq"


def this_host() -> str:
    return socket.gethostname().split(".")[0]


def plan(spec: LaunchSpec, host: str | None = None) -> Part:
    """The part of `spec` that `host` (default: this machine, when the file names it) starts."""
    if host is not None and spec.hosts and host not in spec.hosts:
        raise PlanError(
            f"--host {host}: the file declares the hosts {', '.join(sorted(spec.hosts))}"
        )
    if host is None and spec.hosts:
        mine = this_host()
        host = mine if mine in spec.hosts else None
    chosen = [s for s in spec.services if host is None or s.host in (None, host)]
    others = {s.name: s.host or "" for s in spec.services if s not in chosen}
    naming = spec.naming
    here = naming is not None and (host is None or naming.host in (None, host))
    url = spec.naming_url
    discover = False
    if url is None and naming is not None:
        address = naming.endpoint.split("://", 1)[1].rsplit(":", 1)
        if here and address[1] == "*":  # a free port, chosen now
            address[1] = str(free_port(address[0]))
            naming.endpoint = f"tcp://{address[0]}:{address[1]}"
        if here:
            if address[0] in ("0.0.0.0", "*"):
                url = f"tcp://127.0.0.1:{address[1]}"
            else:
                url = naming.endpoint
        elif address[1] == "*":
            raise PlanError(
                f"the naming service on {naming.host} takes a free port (*): only its own "
                "host can learn which; give it a port"
            )
        elif address[0] not in ("0.0.0.0", "*", "127.0.0.1", "localhost"):
            url = naming.endpoint
        elif naming.host is not None and spec.hosts.get(naming.host):
            url = f"tcp://{spec.hosts[naming.host]}:{address[1]}"
        elif not naming.announce:
            raise PlanError(
                f"the services of {host} cannot know where the naming service on "
                f'{naming.host} is: it is not announced; give [launch] naming = "tcp://'
                f'ADDRESS:PORT", or [hosts.{naming.host}] address'
            )
        else:
            discover = True  # what the naming host announces (mDNS; on Zenoh, its router)
    for s in chosen:
        for dep in s.after:
            if dep in others:
                raise PlanError(
                    f"{s.name} starts after {dep}, which runs on {others[dep] or 'another host'}:"
                    f" make it wait for a name that {dep} binds instead"
                )
    services = list(chosen)
    if naming is not None and here:
        services.insert(0, naming_service(spec))
    return Part(host, services, url, others, discover)


def free_port(host: str) -> int:
    """A TCP port free on `host` now (the naming service binds it a moment later)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("0.0.0.0" if host == "*" else host, 0))
        return int(s.getsockname()[1])


def naming_service(spec: LaunchSpec) -> ServiceSpec:
    """The naming service as a service of the launch: `miro naming` with its channels."""
    assert spec.naming is not None
    n = spec.naming
    argv = [sys.executable, "-u", "-m", "miro_gen.cli.main", "naming", "--endpoint", n.endpoint]
    if backbone(spec) == "zenoh":  # the Zenoh router and the registry beside it
        argv.append("--zenoh")
    if n.insecure:
        argv.append("--insecure")
    if n.per_robot:  # (miro naming refuses it without Zenoh and a key, saying so)
        argv += ["--per-robot", ",".join(n.per_robot)]
    for channel in n.channels:
        argv += ["--channel", channel]
    address = spec.hosts.get(n.host or "") if n.host else None
    if n.channels and address and "0.0.0.0" in n.endpoint:
        argv += ["--host", address]
    if n.log_level is not None:
        argv += ["-MLL", str(n.log_level)]
    if not n.announce:
        argv.append("--no-announce")
    return ServiceSpec(
        name=NAMING_LABEL,
        argv=argv,
        python=False,
        cwd=spec.folder,
        line=n.line,
        host=n.host,
        ready=NAMING_READY,
        restart=n.restart,
    )


@dataclass
class Child:
    """A service and the process running it now (if any)."""

    spec: ServiceSpec
    depth: int = 1  # stopping order: higher first
    state: str = "waiting"
    waiting_for: str = ""
    proc: subprocess.Popen[str] | None = None
    reader: threading.Thread | None = None
    ready: threading.Event = field(default_factory=threading.Event)
    restarts: int = 0
    series: int = 0  # consecutive restarts without a stable run
    last_exit: str = ""
    started: float | None = None
    up_since: float | None = None
    next_start: float = 0.0
    was_up: bool = False  # it has been up at least once

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def finished(self) -> bool:
        return self.state in ("exited", "failed", "gave up", "stopped")


def exit_text(code: int) -> str:
    if code >= 0:
        return f"status {code}"
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


class Supervisor:
    """Runs `part` of `spec`, writing to `console`, until `stop()` or a required service fails;
    `run()` returns the exit status (0, or 1 when a required service could not stay up)."""

    def __init__(self, spec: LaunchSpec, part: Part, console: Console) -> None:
        self.spec = spec
        self.part = part
        self.console = console
        self.children = [Child(s) for s in part.services]
        self.by_name = {c.name: c for c in self.children}
        self.wake = threading.Event()
        self.stopping = threading.Event()
        self.force = threading.Event()
        self.failure: str | None = None
        self.watcher: NameWatcher | None = None
        self.workdir = Path(tempfile.mkdtemp(prefix="miro-launch-"))
        self.project = project_root(spec.folder)
        self.started_order: list[Child] = []
        self.naming_url = part.naming_url
        self.tree: ProcessTree | None = None  # from run(): the process groups it owns
        self._signals = os.pipe()  # stop_from_signal -> _stop_on_signals
        self._signals_closed = False
        threading.Thread(target=self._stop_on_signals, name="launch-signals", daemon=True).start()

    # ---- the loop -------------------------------------------------------------------------------

    def run(self) -> int:
        if self.naming_url is not None:
            self.watcher = NameWatcher(self.naming_url, self.wake, backbone(self.spec))
        elif self.part.discover:
            threading.Thread(target=self._discover, name="launch-discover", daemon=True).start()
        self.console.show_table(self.rows)
        self.tree = ProcessTree(self.spec.grace, self.console.note)
        try:
            while not self.stopping.is_set():
                self._turn()
                if self.failure is not None or self._all_finished():
                    break
                self.wake.wait(POLL)
                self.wake.clear()
        finally:
            self._stop_all()
            self.tree.close()
            if self.watcher is not None:
                self.watcher.close()
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.console.close()
            self._signals_closed = True  # (before the close: handlers run on this thread too)
            os.close(self._signals[1])  # its thread reads the end of the pipe and returns
        if self.failure is not None:
            self.console.note(f"stopped: {self.failure}")
            return 1
        return 0

    def _discover(self) -> None:
        """Look for the announced naming service until one is seen (or the launch stops)."""
        from miro_gen.transport.naming.discovery import FIND_TIMEOUT, DiscoveryOff, browse

        while not self.stopping.is_set():
            try:
                found = browse(FIND_TIMEOUT, first=True, backbone=backbone(self.spec))
            except DiscoveryOff as e:  # nothing to find: the file must name its naming service
                self.console.note(f"cannot look for the naming service: {e}")
                return
            except Exception as e:  # no multicast here: say so once, keep trying
                self.console.note(f"cannot look for the naming service: {e}")
                found = []
                self.stopping.wait(5)
            if found:
                url = found[0].url()
                self.console.note(f"naming service found at {url}, announced by {found[0].host}")
                self.watcher = NameWatcher(url, self.wake, backbone(self.spec))
                self.naming_url = url
                self.wake.set()
                return

    def stop(self) -> None:
        """Stop everything (from another thread; a signal handler calls `stop_from_signal`);
        a second call kills."""
        if self.stopping.is_set():
            self.force.set()
        self.stopping.set()
        self.wake.set()

    def stop_from_signal(self) -> None:
        """`stop()`, safe in a signal handler. A handler runs on the main thread between two
        bytecodes, possibly while that thread holds the lock of the Event it is waiting on;
        `Event.set()` there would wait for that lock forever. So the handler only writes a
        byte to a pipe (no lock) and a thread of the supervisor calls `stop()`."""
        if not self._signals_closed:
            with contextlib.suppress(OSError):
                os.write(self._signals[1], b"s")

    def _stop_on_signals(self) -> None:
        """The thread behind `stop_from_signal`: one `stop()` per byte, until the pipe closes."""
        while True:
            try:
                got = os.read(self._signals[0], 16)
            except OSError:
                return
            if not got:
                os.close(self._signals[0])
                return
            for _ in got:
                self.stop()

    def _all_finished(self) -> bool:
        services = [c for c in self.children if c.name != NAMING_LABEL]
        return bool(services) and all(c.finished for c in services)

    def _turn(self) -> None:
        now = time.monotonic()
        if self.tree is not None:
            self.tree.check()
        for c in self.children:
            if c.proc is not None and c.proc.poll() is not None:
                self._ended(c, now)
            if c.state == "starting" and c.ready.is_set():
                c.state = "up"
                c.up_since = now
                c.was_up = True
                if c.spec.ready:
                    self.console.note(f"{c.name} is up", routine=True)
            if c.state == "waiting" or (c.state == "restarting" and now >= c.next_start):
                reason = self._blocked(c)
                c.waiting_for = reason
                if not reason:
                    self._start(c)

    def _blocked(self, c: Child) -> str:
        """What `c` still waits for ('' when nothing)."""
        if c.name == NAMING_LABEL:
            return ""
        if self.part.discover and self.watcher is None:
            return "an announced naming service"
        if self.watcher is not None and not self.watcher.answering:
            return f"the naming service at {self.watcher.url}"
        for dep in c.spec.after:
            other = self.by_name.get(dep)
            if other is not None:
                if other.state != "up":
                    return dep
            elif self.watcher is None:
                return f"{dep} (no naming service is known)"
            elif not self.watcher.bound(dep, c.spec.context or this_host()):
                return dep
        return ""

    # ---- processes ------------------------------------------------------------------------------

    def _start(self, c: Child) -> None:
        spec = c.spec
        assert self.tree is not None
        try:
            argv, env = self._command(c)
            proc = subprocess.Popen(
                argv,
                cwd=spec.cwd,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                encoding="utf-8",
                errors="replace",
                # a session and process group of its own, owned by the tree: Ctrl-C reaches
                # the launch only, which stops them in order
                start_new_session=True,
            )
        except (OSError, ValueError) as e:
            self.console.note(f"{c.name} cannot start: {e}")
            self._ended(c, time.monotonic(), 127)
            return
        c.proc = proc
        c.ready.clear()
        if spec.ready is None:
            c.ready.set()
        c.state = "starting"
        c.started = time.monotonic()
        c.up_since = None
        if c not in self.started_order:
            self.started_order.append(c)
            earlier = [o.depth for o in self.started_order if o is not c]
            deps = [self.by_name[d].depth for d in spec.after if d in self.by_name]
            names = any(d not in self.by_name for d in spec.after)
            c.depth = (
                0 if c.name == NAMING_LABEL else 1 + max([*deps, *(earlier if names else []), 0])
            )
        self.tree.own(proc.pid, c.depth)
        c.reader = threading.Thread(target=self._copy, args=(c, proc), daemon=True)
        c.reader.start()
        again = f" (restart {c.restarts})" if c.restarts else ""
        self.console.note(f"{c.name} started, pid {proc.pid}{again}", routine=not c.restarts)

    def _command(self, c: Child) -> tuple[list[str], dict[str, str]]:
        spec = c.spec
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"
        env["MIRO_SERVICE"] = spec.name
        if self.naming_url is not None:
            env["MIRO_NAMING"] = self.naming_url
        address = self.spec.hosts.get(spec.host or "") if spec.host else None
        if address:
            env["MIRO_HOST"] = address
        generated = self.project / "generated"
        if generated.is_dir():  # a checkout or project: its generated code and packages first
            env["PYTHONPATH"] = os.pathsep.join(
                [str(generated), str(self.project), *filter(None, [env.get("PYTHONPATH")])]
            )
        if spec.transport is not None:
            env["MIRO_TRANSPORT"] = spec.transport
        if spec.fleet_events is not None:
            from miro_gen.transport.zenoh.fleet import FLEET_ENV, text_of

            env[FLEET_ENV] = text_of(spec.fleet_events)
        env.update(spec.env)
        params = ""
        if spec.params_file is not None or spec.parameters:
            params = str(
                write_parameters(
                    self.workdir / f"{spec.name}.xml", spec.params_file, spec.parameters
                )
            )
        values = placeholders(self.spec, spec, env.get("MIRO_NAMING", ""), params)
        argv = [fill(word, values) for word in spec.argv]
        if spec.python:
            if spec.context:
                argv += ["-MNC", spec.context]
            if params:
                argv += ["-MCF", params]
            if spec.log_level is not None:
                argv += ["-MLL", str(spec.log_level)]
        return argv, env

    def _copy(self, c: Child, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        with proc.stdout:
            for text in proc.stdout:
                self.console.line(c.name, text.rstrip("\n"))
                if c.spec.ready and not c.ready.is_set() and c.spec.ready in text:
                    c.ready.set()
                    self.wake.set()
        self.wake.set()

    def _ended(self, c: Child, now: float, code: int | None = None) -> None:
        if c.proc is not None:
            code = c.proc.wait()
            if c.reader is not None:
                c.reader.join(2)
            if self.tree is not None:
                self.tree.prune(c.proc.pid)
            c.proc = None
        assert code is not None
        c.last_exit = exit_text(code)
        ran = now - (c.started or now)
        if self.stopping.is_set():
            c.state = "stopped"
            return
        policy: RestartPolicy = c.spec.restart
        if ran >= policy.stable_after:
            c.series = 0
        if policy.wants_restart(code):
            if policy.limit is None or c.series < policy.limit:
                c.series += 1
                c.restarts += 1
                delay = policy.backoff(c.series)
                c.state = "restarting"
                c.next_start = now + delay
                limit = f" of {policy.limit}" if policy.limit is not None else ""
                self.console.note(
                    f"{c.name} exited with {c.last_exit}; restart {c.series}{limit} in {delay:g} s"
                )
                return
            c.state = "gave up"
            why = f"exited with {c.last_exit} after {c.restarts} restarts"
        elif code == 0:
            c.state = "exited"
            self.console.note(f"{c.name} exited with status 0", routine=True)
            return
        else:
            c.state = "failed"
            why = f"exited with {c.last_exit}"
        if c.spec.required or c.name == NAMING_LABEL:
            self.failure = f"{c.name} could not stay up: it {why}"
        self.console.note(f"{c.name} {why}; given up")

    # ---- stopping -------------------------------------------------------------------------------

    def _stop_all(self) -> None:
        self.stopping.set()
        running = [c for c in self.children if c.proc is not None]
        if running:
            names = ", ".join(c.name for c in reversed(running))
            self.console.note(f"stopping {names}", routine=True)
        for depth in sorted({c.depth for c in running}, reverse=True):
            wave = [c for c in running if c.depth == depth]
            groups = [c.proc.pid for c in wave if c.proc is not None]
            for c in wave:
                c.state = "stopping"
                _signal(c, signal.SIGTERM)
            end = time.monotonic() + self.spec.grace
            # until the services and what they started (their groups and sessions) are gone
            while any(c.proc is not None and c.proc.poll() is None for c in wave) or left(groups):
                if time.monotonic() >= end or self.force.is_set():
                    for c in wave:
                        if c.proc is not None and c.proc.poll() is None:
                            what = f"{c.name} did not stop"
                        elif c.proc is not None and left([c.proc.pid]):
                            what = f"what {c.name} started did not stop"
                        else:
                            continue
                        self.console.note(f"{what} within {self.spec.grace:g} s: killed")
                    kill(groups)
                    break
                time.sleep(0.02)
            for c in wave:
                self._ended(c, time.monotonic())
        if self.tree is not None:  # what the services left in their groups and sessions
            self.tree.kill_all()
        for c in self.children:
            if c.state in ("waiting", "restarting", "starting", "up"):
                c.state = "stopped"
        if running:
            self.console.note("all stopped", routine=True)

    # ---- the status table -----------------------------------------------------------------------

    def rows(self) -> list[Row]:
        out: list[Row] = [("SERVICE", "STATE", "PID", "RESTARTS", "LAST EXIT", "UP")]
        now = time.monotonic()
        for c in self.children:
            state = c.state
            if state == "waiting" and c.waiting_for:
                state = f"waiting for {c.waiting_for}"
            elif state == "restarting":
                state = f"restarting in {max(c.next_start - now, 0):.1f} s"
            elif state == "starting" and c.spec.ready:
                state = f"starting (until {c.spec.ready!r})"
            pid = str(c.proc.pid) if c.proc is not None else ""
            up = since(c.up_since) if c.state == "up" else ""
            out.append((c.name, state, pid, str(c.restarts), c.last_exit, up))
        return out

    @property
    def all_came_up(self) -> bool:
        """Whether every service has been up at least once."""
        return all(c.was_up for c in self.children)

    def status(self) -> dict[str, Any]:
        """The children's states by name (for tests and tools)."""
        return {c.name: (c.state, c.restarts, c.last_exit) for c in self.children}


def _signal(c: Child, sig: int) -> None:
    """`sig` to the service's process group and session (launch.tree)."""
    if c.proc is None:
        return
    send([c.proc.pid], sig)


def placeholders(
    launch: LaunchSpec, service: ServiceSpec, naming: str, params: str
) -> dict[str, str]:
    """The values of the placeholders in `service`'s command: its name, the naming service
    (`naming`), its naming context, the launch file's folder, its host's address and its
    parameter document (`params`, written when it starts)."""
    address = launch.hosts.get(service.host or "") if service.host else None
    return {
        "name": service.name,
        "naming": naming,
        "context": service.context or this_host(),
        "dir": str(launch.folder),
        "host": address or "",
        "params": params,
    }


def fill(word: str, values: dict[str, str]) -> str:
    """`word` with its placeholders ({naming}, ...) filled in; `{{` and `}}` are braces."""
    return word.format_map(values) if "{" in word or "}" in word else word
