"""The launch's process tree: the services' sessions, and a watcher that stops them when the
launch itself is killed.

Each service starts a session of its own (and so a process group of its own, with the same
id): SIGTERM and SIGKILL go to the whole group, and, on Linux, to every process still in the
session, so that a child the service moved to a process group of its own (a shell with job
control does) goes too. Only a process that starts a session of its own (a daemon) leaves.

A launch killed outright (SIGKILL, the OOM killer, a crash) cannot stop anything. So it starts
a *watcher* first: a small process in a session of its own (Ctrl-C and a closed terminal do
not reach it) that reads, from a pipe, the groups the launch owns and the order in which to
stop them (`own PGID DEPTH`, `gone PGID`, and `done` at a clean end). When the pipe ends
without `done`, the launch is gone: the watcher sends SIGTERM to the services in waves (the
deepest first, the naming service last) and SIGKILL to whatever is left once the launch's
grace period has passed, then ends. The kernel closes the pipe whatever way the launch dies,
so nothing depends on the launch's last moments.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Collection

POLL = 0.02  # seconds between looks at what is left while stopping
KILL_ROUNDS = 50  # SIGKILL again while processes are still seen (a fork caught mid-way)
WATCHER_STARTS = 10  # a watcher that keeps ending is given up, saying so


# ---- the processes of a group or session -------------------------------------------------------


def members(ids: Collection[int]) -> list[tuple[int, int]]:
    """(pid, process group) of the live processes whose process group or session is one of
    `ids` (Linux: from /proc; elsewhere, none: process groups are all there is). Zombies are
    not counted: they are dead, waiting for their parent to reap them."""
    if not ids or not os.path.isdir("/proc/self"):
        return []
    found = []
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat", "rb") as f:
                stat = f.read()
        except OSError:  # ended meanwhile
            continue
        # pid (comm) state ppid pgrp session ...: comm may hold anything, even ")"
        fields = stat[stat.rfind(b")") + 2 :].split()
        if len(fields) < 4 or fields[0] == b"Z":
            continue
        group, session = int(fields[2]), int(fields[3])
        if group in ids or session in ids:
            found.append((int(entry.name), group))
    return found


def send(ids: Collection[int], sig: int) -> None:
    """Send `sig`, once, to every process of the process groups `ids` and of the sessions
    `ids` (those in another group of the session too)."""
    for pgid in ids:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(pgid, sig)
    for pid, group in members(ids):
        if group not in ids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)


def left(ids: Collection[int]) -> int:
    """How many processes (not zombies) are left in the groups and sessions `ids` (elsewhere
    than on Linux: how many of the groups are left)."""
    if os.path.isdir("/proc/self"):
        return len(members(ids))
    count = 0
    for pgid in ids:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            continue
        except PermissionError:
            pass
        count += 1
    return count


def kill(ids: Collection[int]) -> int:
    """SIGKILL to the groups and sessions `ids` until nothing is left in them (a process that
    forked as the first signal came has a child the next one reaches); how many there were."""
    there = left(ids)
    for _ in range(KILL_ROUNDS if there else 0):
        send(ids, signal.SIGKILL)
        time.sleep(POLL)
        if not left(ids):
            break
    return there


# ---- the launch's side -------------------------------------------------------------------------


class ProcessTree:
    """The process groups a launch owns, told to its watcher as they come and go. `note`
    receives what a user should know (the watcher could not be started, or ended)."""

    def __init__(self, grace: float, note: Callable[[str], None]) -> None:
        self.grace = grace
        self.depths: dict[int, int] = {}  # process group -> stopping order (higher first)
        self._note = note
        self._watcher: subprocess.Popen[bytes] | None = None
        self._starts = 0
        self._start_watcher()

    def _start_watcher(self) -> None:
        """Start the watcher (again, at most WATCHER_STARTS times) and tell it everything."""
        self._watcher = None
        if self._starts >= WATCHER_STARTS:
            self._note("no watcher: a launch killed outright would leave its services running")
            return
        self._starts += 1
        try:
            watcher = subprocess.Popen(
                [sys.executable, "-m", __name__, str(os.getpid()), repr(self.grace)],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                # Ctrl-C to the launch, or its terminal closing, is not its end; the launch's is
                start_new_session=True,
            )
        except OSError as e:
            self._note(f"cannot start the watcher: {e}")
            self._starts = WATCHER_STARTS
            self._start_watcher()  # (says what that means)
            return
        assert watcher.stdin is not None
        os.set_blocking(watcher.stdin.fileno(), False)
        self._watcher = watcher
        for pgid, depth in self.depths.items():
            self._tell(f"own {pgid} {depth}")

    def _tell(self, line: str) -> None:
        watcher = self._watcher
        if watcher is None or watcher.stdin is None:
            return
        try:
            os.write(watcher.stdin.fileno(), (line + "\n").encode())
        except BrokenPipeError:  # it ended: another, told everything
            self._replace(watcher)
        except BlockingIOError:  # it does not read (stopped?)
            self._note(f"the watcher does not read: it was not told {line!r}")

    def _replace(self, watcher: subprocess.Popen[bytes]) -> None:
        assert watcher.stdin is not None
        with contextlib.suppress(OSError):
            watcher.stdin.close()
        code = watcher.wait()
        self._start_watcher()
        if self._watcher is not None:
            self._note(
                f"the watcher (pid {watcher.pid}) ended with {code}; another started (pid "
                f"{self._watcher.pid})"
            )

    def check(self) -> None:
        """Start the watcher again if it ended (the launch calls this now and then)."""
        if self._watcher is not None and self._watcher.poll() is not None:
            self._replace(self._watcher)

    def own(self, pgid: int, depth: int) -> None:
        """A service started as the leader of process group (and session) `pgid`; `depth` is
        its place in the stopping order (the deepest first)."""
        self.depths[pgid] = depth
        self._tell(f"own {pgid} {depth}")

    def prune(self, pgid: int) -> None:
        """Forget `pgid` when nothing is left in it: its number may be another process's
        some day."""
        if pgid in self.depths and not left([pgid]):
            del self.depths[pgid]
            self._tell(f"gone {pgid}")

    def kill_all(self) -> None:
        """SIGKILL to whatever is left in every group and session owned; then forget them."""
        kill(self.depths)
        for pgid in list(self.depths):
            self.prune(pgid)

    def close(self) -> None:
        """The launch ends cleanly: the watcher ends without doing anything."""
        watcher, self._watcher = self._watcher, None
        if watcher is None or watcher.stdin is None:
            return
        with contextlib.suppress(OSError):
            os.set_blocking(watcher.stdin.fileno(), True)
            watcher.stdin.write(b"done\n")
        with contextlib.suppress(OSError):
            watcher.stdin.close()
        try:
            watcher.wait(5)
        except subprocess.TimeoutExpired:
            watcher.kill()
            watcher.wait()


# ---- the watcher ---------------------------------------------------------------------------------


def watch(launch_pid: int, grace: float) -> int:
    """Read what the launch owns from the standard input until it ends; when it ends without
    `done`, stop all of it (SIGTERM in waves, SIGKILL after `grace` seconds)."""
    for sig in (signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    depths: dict[int, int] = {}
    for raw in sys.stdin.buffer:
        word, *args = raw.decode(errors="replace").split() or [""]
        if word == "done":
            return 0
        if word == "own" and len(args) == 2:
            depths[int(args[0])] = int(args[1])
        elif word == "gone" and args:
            depths.pop(int(args[0]), None)
    if not left(depths):
        return 0
    _say(
        f"miro launch (pid {launch_pid}) ended without stopping its services: stopping them "
        f"(SIGTERM, then SIGKILL after {grace:g} s)"
    )
    deadline = time.monotonic() + grace
    for depth in sorted(set(depths.values()), reverse=True):
        wave = [pgid for pgid, d in depths.items() if d == depth]
        send(wave, signal.SIGTERM)
        while left(wave) and time.monotonic() < deadline:
            time.sleep(POLL)
        if time.monotonic() >= deadline:
            break
    if left(depths):
        killed = kill(depths)
        _say(f"miro launch (pid {launch_pid}): {killed} process(es) left after {grace:g} s: killed")
    return 0


def _say(text: str) -> None:
    with contextlib.suppress(OSError):  # a terminal that is gone
        print(f"launch watcher: {text}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    sys.exit(watch(int(sys.argv[1]), float(sys.argv[2])))
