"""Who may change a name, tried as an attacker on the same machine would (issue 33), between real
processes: a stranger of another user (`setpriv`, when the tests run as root), a stranger of
the same user claiming another service, and one that talks TCP to the naming service instead
of its Unix socket; strangers polling `bind` every 20 ms while the naming service or a server
is killed and restarted (also under `miro launch`); made-up owners against the quota; and
listing a full table. The seconds the restarts take are in bench/bench_restarts.py."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import Miro
import MiroNaming
import MiroService
import pytest
import zmq
from loopback import NamingProcess, eventually, free_port, run_miro, service_env
from miro_cli import REPO
from repo_paths import TESTS

from miro_gen import NO_RESOURCES, TRANSIENT, Client
from miro_gen.testing import ServiceProcess

HERE = TESTS
EXAMPLE = HERE / "procs" / "named_example.py"
STRANGER = HERE / "procs" / "naming_stranger.py"
EVIL = "tcp://10.66.6.6:666"  # the endpoint strangers bind
LEASE = "1.5"  # seconds: the servers' leases, short so that a dead one's ends soon
NOBODY = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
other_user = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("setpriv") is None,
    reason="running a stranger as another user needs root and setpriv",
)


class Victim:
    """named_example.py binding `names` under the context `r` (its service: r/named_example);
    what it says on stderr is kept."""

    def __init__(self, naming: NamingProcess, *names: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(EXAMPLE), "--naming", naming.endpoint, "-MNC", "r", *names],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=service_env(MIRO_TEST_LEASE=LEASE),
        )
        self.err: list[str] = []
        assert self.proc.stderr is not None
        threading.Thread(target=self._read, args=(self.proc.stderr,), daemon=True).start()
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "READY", self.err

    def _read(self, stream: object) -> None:
        for line in stream:  # type: ignore[attr-defined]
            self.err.append(line)

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait(10)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(10)


class Stranger:
    """naming_stranger.py polling `bind` of `name` as `service` every 20 ms, as another user
    (`as_nobody`) or this one; `result()` stops it and says how its tries ended."""

    def __init__(self, naming: str, name: str, service: str, as_nobody: bool) -> None:
        self.proc = stranger_process(naming, "poll", name, service, as_nobody=as_nobody)
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().strip() == "STARTED"

    def result(self) -> dict[str, int]:
        out, _ = self.proc.communicate("", timeout=30)
        outcomes: dict[str, int] = json.loads(out)["outcomes"]
        return outcomes


def stranger_process(
    naming: str, *args: str, as_nobody: bool = False, tcp: bool = False
) -> subprocess.Popen[str]:
    """naming_stranger.py `args` against the naming service at `naming`."""
    command = [sys.executable, str(STRANGER), naming, *(["--tcp"] if tcp else []), *args]
    return subprocess.Popen(
        [*NOBODY, *command] if as_nobody else command,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=service_env(),
    )


def stranger_once(naming: NamingProcess, *args: str, **how: bool) -> dict[str, str]:
    proc = stranger_process(naming.endpoint, *args, **how)
    out, _ = proc.communicate("", timeout=60)
    result: dict[str, str] = json.loads(out)
    return result


@pytest.fixture
def naming() -> Iterator[NamingProcess]:
    n = NamingProcess()
    yield n
    n.stop()


def client(naming: NamingProcess | str) -> Client:
    endpoint = naming if isinstance(naming, str) else naming.endpoint
    return Client(["t", "--naming", endpoint], context=zmq.Context())


class Watch:
    """Resolves `name` every 10 ms in a thread of its own, keeping each endpoint seen."""

    def __init__(self, naming: str, name: str) -> None:
        self.client = client(naming)
        self.name = name
        self.seen: set[str] = set()
        self.misses = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            try:
                self.seen.add(self.client.naming.resolve(self.name).endpoint)
            except Exception:  # not bound just now, or the naming service restarting
                self.misses += 1

    def stop(self) -> set[str]:
        self._stop.set()
        self._thread.join(10)
        self.client.close()
        return self.seen


# ---- owners ------------------------------------------------------------------------------------


@other_user
def test_another_user_can_take_or_remove_no_name(naming: NamingProcess) -> None:
    """Before: the owner was a string the client sent. Now the naming service knows the user
    of a process on its machine from the kernel: another user is refused whatever service it
    claims, the victim's own included."""
    victim = Victim(naming, "A")
    try:
        tried = stranger_once(naming, "try", "r/A", "r/named_example", as_nobody=True)
        assert tried["bind"] == "AlreadyBound: another user or host (live)"
        assert tried["take_over"] == "AlreadyBound: another user or host (live)"
        assert tried["unbind"] == "NotFound"
        assert tried["renew"] == "ok ['r/A']"  # not its name: lost, as far as it is concerned
        victim.kill()  # its lease ends, the name is kept for its user
        c = client(naming)
        eventually(lambda: not _resolves(c, "r/A"))
        c.close()
        tried = stranger_once(naming, "try", "r/A", "r/named_example", as_nobody=True)
        assert tried["take_over"].startswith("AlreadyBound: another user or host (its server")
    finally:
        victim.stop()


def test_another_service_of_the_same_user_takes_no_name_live_or_kept(
    naming: NamingProcess,
) -> None:
    """A process of the same user is inside the trust boundary (it could kill the server), but
    a name is its service's, live or kept after its server stopped: a second program binding
    it, or a stranger polling, is told who holds it. The user frees a kept name by hand."""
    victim = Victim(naming, "A", "B")
    c = client(naming)
    try:
        honest = c.naming.resolve("r/A")
        tried = stranger_once(naming, "try", "r/A", "r/stranger")
        assert tried == {
            "bind": "AlreadyBound: r/named_example, another service of yours",
            "take_over": "AlreadyBound: r/named_example, another service of yours",
            "unbind": "NotFound",
            "renew": "ok ['r/A']",
        }
        time.sleep(2 * float(LEASE))  # leases renewed meanwhile: nothing changed hands
        assert c.naming.resolve("r/A") == honest
        assert c.resolve_name("r/B", Miro.Example).getData() == Miro.ExampleStructIDL(1.0, 1.0)
        victim.kill()
        eventually(lambda: not _resolves(c, "r/A"))  # its lease ended: kept
        tried = stranger_once(naming, "try", "r/B", "r/stranger")
        kept = "AlreadyBound: r/named_example, another service of yours, kept since its server"
        assert tried["bind"].startswith(kept) and tried["take_over"].startswith(kept)
        assert tried["unbind"] == "ok"  # the user's own: freed on purpose, as nsunbind does
        out = run_miro("nsunbind", "--naming", naming.endpoint, "r/A", "r/nothing")
        assert out.stdout.splitlines() == ["freed r/A"]
        assert out.returncode == 1 and "r/nothing is not kept for you" in out.stderr
        polled = Stranger(naming.endpoint, "r/A", "r/stranger", as_nobody=False)
        eventually(lambda: _endpoint(c, "r/A") == EVIL)  # free: anyone's
        polled.result()
    finally:
        c.close()
        victim.stop()


def test_owner_calls_over_loopback_tcp_are_refused(naming: NamingProcess) -> None:
    """Over TCP from this machine any user may pose as any other (and pick any address of
    127/8): where the Unix socket exists, calls that need an owner must come through it."""
    victim = Victim(naming, "A")
    try:
        tried = stranger_once(naming, "try", "r/A", "r/named_example", tcp=True)
        for outcome in tried.values():
            assert outcome.startswith("NO_PERMISSION: processes on the naming service's machine")
        c = client(naming)
        assert c.naming.resolve("r/A").endpoint != EVIL  # reading stays open to everyone
        c.close()
    finally:
        victim.stop()


@other_user
def test_made_up_owners_cannot_exceed_one_users_quota() -> None:
    """Before: 22,000 binds under made-up owners from one process filled the 20,000-name table
    in 2.3 s, and every server started after exited. Now the quota is per user (or host),
    whatever owners it makes up; other users keep theirs, and a full table still lists."""
    naming = NamingProcess(options=("--quota", "20", "--max-names", "30"))
    try:
        filled = stranger_once(naming, "fill", "junk", "100", as_nobody=True)
        assert filled["outcomes"] == {"ok": 20, "NO_RESOURCES": 80}  # type: ignore[comparison-overlap]
        victim = Victim(naming, "A")  # another user: its own quota
        c = client(naming)
        assert c.naming.resolve("r/A").endpoint != EVIL
        filled = stranger_once(naming, "fill", "mine", "100")  # this user's own junk
        assert filled["outcomes"] == {"ok": 8, "NO_RESOURCES": 92}  # type: ignore[comparison-overlap]
        assert len(c.naming.entries()) == 30  # the table is full, and lists
        out = run_miro("nslist", "--naming", naming.endpoint)
        assert out.returncode == 0 and "junk/" in out.stdout and "  A  (" in out.stdout
        out = run_miro("list", "--naming", naming.endpoint)
        assert out.returncode == 0, out.stderr
        assert "named_example" in out.stdout
        c.close()
        victim.stop()
    finally:
        naming.stop()


def test_a_full_table_of_the_largest_entries_lists_in_pages() -> None:
    """Before: 1,800 entries of the largest size made `list` 9 MB, over the message limit, and
    `miro nslist` and `miro list` failed. Here the limit is 256 KiB and the table 600 entries
    of 2 KiB (1.2 MB): both list it."""
    options = ("--max-names", "600", "--quota", "600", "--max-message-size", "256K")
    naming = NamingProcess(options=options)
    victim = Victim(naming, "A")
    c = Client(["t", "--naming", naming.endpoint, "--max-message-size", "256K"])
    registry = c.naming.registry_stub(c.invoker, 5.0, owner=True)
    me = MiroNaming.Owner("big/filler", "1")
    try:
        for n in range(600):
            name = f"big/{n:04d}/" + "n" * 900  # name + endpoint + key + type hash: 2 KiB
            entry = MiroNaming.Entry(name, "IDL:x:1.0", "tcp://" + "e" * 500, b"k" * 500, "h" * 40)
            try:
                registry.bind_as(entry, me, 60_000, False)
            except NO_RESOURCES:  # the victim's two names and these: 600
                break
        assert len(c.naming.entries()) == 600
        for args in (("nslist",), ("list",)):
            out = run_miro(*args, "--naming", naming.endpoint, "--max-message-size", "256K")
            assert out.returncode == 0, out.stderr
            assert "named_example" in out.stdout or "A  (" in out.stdout
    finally:
        c.close()
        victim.stop()
        naming.stop()


# ---- restarts ----------------------------------------------------------------------------------


def strangers(naming: str, name: str) -> list[Stranger]:
    """A stranger of this user claiming another service, and (as root) one of another user
    claiming the victim's own: both poll `bind` every 20 ms."""
    found = [Stranger(naming, name, "r/stranger", as_nobody=False)]
    if os.geteuid() == 0 and shutil.which("setpriv"):
        found.append(Stranger(naming, name, "r/named_example", as_nobody=True))
    return found


def test_a_restarted_naming_service_hands_no_name_to_a_polling_stranger(
    naming: NamingProcess,
) -> None:
    """Before: a stranger calling `bind` every 20 ms took every name when the naming service
    restarted, before the servers' next renewal, and kept them (3 of 3). Now the naming
    service reads its log of owners back before it answers anyone."""
    victim = Victim(naming, "A")
    c = client(naming)
    honest = c.naming.resolve("r/A").endpoint
    polling = strangers(naming.endpoint, "r/A")
    watch = Watch(naming.endpoint, "r/A")
    try:
        for _ in range(3):
            naming.restart(signal.SIGKILL)
            eventually(lambda: _resolves(c, "r/A"))
            time.sleep(float(LEASE))  # the strangers have a lease's time to try
        for s in polling:
            outcomes = s.result()
            assert outcomes.get("ok", 0) == 0 and outcomes.get("AlreadyBound", 0) > 0, outcomes
        assert watch.stop() == {honest}
        assert c.naming.resolve("r/A").endpoint == honest
        assert not [line for line in victim.err if "held by" in line or "taken by" in line]
    finally:
        c.close()
        victim.stop()


def test_a_restarted_server_gets_its_names_back_at_once_and_a_stranger_never(
    naming: NamingProcess,
) -> None:
    """Before: the stranger bound the name when the dead server's lease ended (2.1-2.2 s) and
    the restarted server exited with AlreadyBound (3 of 3); without a stranger, the restarted
    server waited for its predecessor's lease, with a warning. Now the restart takes the name
    over as it binds (resolvable as soon as it says READY), whether the dead one's lease still
    runs or has ended (the name kept for its user), and says nothing about it."""
    victim = Victim(naming, "A")
    c = client(naming)
    polling = strangers(naming.endpoint, "r/A")
    watch = Watch(naming.endpoint, "r/A")
    endpoints = {c.naming.resolve("r/A").endpoint}
    try:
        for wait_for_the_lease in (False, True, False):
            victim.kill()
            if wait_for_the_lease:
                eventually(lambda: not _resolves(c, "r/A"))
                time.sleep(float(LEASE))  # kept, and polled for, a while
            victim = Victim(naming, "A")
            mine = c.naming.resolve("r/A").endpoint  # at once: bound before READY
            assert mine not in endpoints and mine != EVIL
            endpoints.add(mine)
            assert c.resolve_name("r/A", Miro.Example).getData() == Miro.ExampleStructIDL(1, 1)
            assert not [line for line in victim.err if "WARNING" in line], victim.err
        for s in polling:
            outcomes = s.result()
            assert outcomes.get("ok", 0) == 0 and outcomes.get("AlreadyBound", 0) > 0, outcomes
        assert watch.stop() <= endpoints
    finally:
        c.close()
        victim.stop()


def test_a_second_copy_of_a_service_takes_its_names_and_the_first_says_so(
    naming: NamingProcess,
) -> None:
    """The same user and service name is the same owner: a second copy started by hand while
    the first runs takes the names over (as a restart would), and the first, finding them
    gone at its next renewal, says so loudly and keeps trying instead of taking them back."""
    first = Victim(naming, "A")
    c = client(naming)
    try:
        second = Victim(naming, "A")
        mine = c.naming.resolve("r/A").endpoint
        eventually(lambda: any("r/A was taken by another run" in line for line in first.err))
        time.sleep(2 * float(LEASE))  # the first keeps trying: the name stays with the second
        assert c.naming.resolve("r/A").endpoint == mine
        assert first.proc.poll() is None  # still serving
        second.stop()  # unbinds: the first, still trying, gets it
        eventually(lambda: _endpoint(c, "r/A") not in (mine, None))
        # (the first's log line may be read a moment after the name is resolvable)
        eventually(lambda: any("bound r/A in the naming service after" in x for x in first.err))
    finally:
        c.close()
        first.stop()


def test_a_server_whose_name_is_taken_keeps_trying_and_says_so() -> None:
    """Before: AlreadyBound after a lease, and exit (a crash loop under `miro launch`). Now a
    warning naming the holder, the server runs, and it binds the name once it is free."""
    naming = NamingProcess(options=("--hold", "0"))  # a stopped server's names: free at once
    other = subprocess.Popen(
        [sys.executable, str(EXAMPLE), "--naming", naming.endpoint, "-MNC", "r", "A"],
        stdout=subprocess.PIPE,
        text=True,
        env=service_env(MIRO_TEST_LEASE=LEASE, MIRO_SERVICE="holder"),
    )
    assert other.stdout is not None and other.stdout.readline().strip() == "READY"
    c = client(naming)
    try:
        waiting = ServiceProcess(
            "tests.procs.named_example", "--naming", naming.endpoint, "-MNC", "r", "A", "B",
            cwd=REPO,
        )  # fmt: skip
        with waiting:
            waiting.wait_for("READY")
            held = waiting.wait_for("r/A is held by")[0]
            assert "holder, another service of yours" in held and "keeps trying" in held
            assert c.resolve_name("r/B", Miro.Example).getData() == Miro.ExampleStructIDL(1, 1)
            other.kill()
            other.wait(10)
            waiting.wait_for("bound r/A in the naming service after")
            stub = c.resolve_name("r/A", Miro.Example)
            assert stub.getData() == Miro.ExampleStructIDL(1.0, 1.0)
    finally:
        c.close()
        if other.poll() is None:
            other.kill()
        naming.stop()


def test_a_service_restarted_by_miro_launch_binds_at_once_and_a_stranger_never(
    tmp_path: Path,
) -> None:
    """Before, without an attacker: a service restarted by `miro launch` was resolvable only
    after its predecessor's lease, and logged "held by another owner"; with one, a crash
    loop. Now the launch's service takes its names over when it starts again."""
    port = free_port()
    (tmp_path / "robot.toml").write_text(
        textwrap.dedent(
            f"""
            [launch]
            context = "r"
            grace = 2

            [naming]
            endpoint = "tcp://127.0.0.1:{port}"
            announce = false

            [services.victim]
            run = "{EXAMPLE}"
            args = ["A"]
            ready = "READY"
            restart = "always"
            restart_delay = 0.1
            env = {{ MIRO_TEST_LEASE = "{LEASE}" }}
            """
        )
    )
    launch = ServiceProcess("miro_gen.cli.main", "launch", str(tmp_path / "robot.toml"), cwd=REPO)
    with launch:
        launch.wait_for("READY")
        naming = f"tcp://127.0.0.1:{port}"  # the launch's
        c = client(naming)
        polling = strangers(naming, "r/A")
        watch = Watch(naming, "r/A")
        try:
            endpoints = {c.naming.resolve("r/A").endpoint}
            for run in (1, 2):
                os.kill(_pid_of(c, "r/_services/victim"), signal.SIGKILL)
                launch.wait_for(f"restart {run} of")
                eventually(lambda: _endpoint(c, "r/A") not in (*endpoints, None), 60)
                endpoints.add(c.naming.resolve("r/A").endpoint)
                assert c.resolve_name("r/A", Miro.Example).getData() == Miro.ExampleStructIDL(
                    1.0, 1.0
                )
            for s in polling:
                outcomes = s.result()
                assert outcomes.get("ok", 0) == 0 and outcomes.get("AlreadyBound", 0) > 0
            assert watch.stop() <= endpoints
            victim = [line for line in launch.lines if line.split("|")[0].strip() == "victim"]
            assert victim and not [line for line in victim if "WARNING" in line], victim
        finally:
            c.close()


def _pid_of(c: Client, service: str) -> int:
    stub = c.resolve_name(service, MiroService.Service)
    pid: int = stub.describe().pid
    return pid


def _endpoint(c: Client, name: str) -> str | None:
    """The endpoint `name` is bound to, or None."""
    try:
        return c.naming.resolve(name).endpoint
    except (MiroNaming.NotFound, TRANSIENT):
        return None


def _resolves(c: Client, name: str) -> bool:
    """Whether `name` is bound (False too while the naming service does not answer)."""
    try:
        c.naming.resolve(name)
    except (MiroNaming.NotFound, TRANSIENT):
        return False
    return True
