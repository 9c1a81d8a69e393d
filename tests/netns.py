"""Linux network namespaces as hosts for tests: a hub namespace with a bridge, and one namespace
per host joined to it by a veth link, with addresses in 10.77.0.0/24 (or another /24); the
processes started in them hold a fleet key (CURVE, and TLS for Zenoh) made for the run.
Skipped, saying why, without root, iproute2 or the right to make namespaces. Shared by the
tests across robots (multihost, discovery, IIOP attacks, a robot's bring-up, Zenoh fleets)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import service_env

ADDRESSES = {"nsbox": "10.77.0.1", "robot": "10.77.0.2", "laptop": "10.77.0.3"}


def ip(*args: str) -> None:
    """Run `ip ARGS`; a failure shows the command and what `ip` said."""
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, f"ip {' '.join(args)}: {done.stderr.strip()}"


class Hosts:
    """Namespaces named after this test run (`miro-<pid>-<host>`) and the processes in them,
    which hold the fleet's key `key` (MIRO_KEYS)."""

    def __init__(self, key: Path, addresses: dict[str, str] | None = None, tag: str = "") -> None:
        self.addresses = ADDRESSES if addresses is None else addresses
        self.prefix = f"miro-{os.getpid()}{tag}-"
        self.created: list[str] = []
        self.procs: list[subprocess.Popen[str]] = []
        # multicast DNS, off for the tests (conftest.py), stays inside these namespaces; their
        # naming services keep their logs of owners beside the key: a namespace deleted frees its
        # inode, which a later one (of another test, with another key) may get.
        self.env = service_env(
            MIRO_KEYS=str(key), MIRO_DISCOVERY="1", XDG_STATE_HOME=str(key.parent)
        )

    def ns(self, host: str) -> str:
        return self.prefix + host

    def wrapper(self, host: str) -> list[str]:
        """What runs a command in `host`'s namespace with the fleet's key (and multicast DNS)."""
        return [
            *("ip", "netns", "exec", self.ns(host), "env"),
            f"MIRO_KEYS={self.env['MIRO_KEYS']}",
            "MIRO_DISCOVERY=1",
            f"XDG_STATE_HOME={self.env['XDG_STATE_HOME']}",
        ]

    def add(self, host: str) -> subprocess.CompletedProcess[str]:
        done = subprocess.run(
            ["ip", "netns", "add", self.ns(host)], capture_output=True, text=True, timeout=30
        )
        if done.returncode == 0:
            self.created.append(self.ns(host))
        return done

    def link(self) -> None:
        """The hub's bridge, and each host's eth0 plugged into it (with lo up)."""
        hub = self.ns("hub")
        ip("-n", hub, "link", "add", "br0", "type", "bridge")
        ip("-n", hub, "link", "set", "br0", "up")
        for host, address in self.addresses.items():
            ns, port = self.ns(host), f"to-{host}"
            ip("-n", hub, "link", "add", port, "type", "veth", "peer", "name", "eth0", "netns", ns)
            ip("-n", hub, "link", "set", port, "master", "br0", "up")
            ip("-n", ns, "addr", "add", f"{address}/24", "dev", "eth0")
            ip("-n", ns, "link", "set", "eth0", "up")
            ip("-n", ns, "link", "set", "lo", "up")

    def popen(
        self,
        host: str,
        *argv: str,
        stderr: Path | None = None,
        env: dict[str, str] | None = None,
    ) -> subprocess.Popen[str]:
        """`argv` (run by this Python) in `host`'s namespace, from this checkout, with `env`
        (default the fleet's); its output (stderr to the file `stderr`, else with stdout)."""
        with stderr.open("w") if stderr is not None else contextlib.nullcontext() as err:
            proc = subprocess.Popen(
                ["ip", "netns", "exec", self.ns(host), sys.executable, *argv],
                stdout=subprocess.PIPE,
                stderr=err if err is not None else subprocess.STDOUT,
                text=True,
                env=self.env if env is None else env,
            )
        self.procs.append(proc)
        return proc

    def run(
        self, host: str, *argv: str, env: dict[str, str] | None = None
    ) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            ["ip", "netns", "exec", self.ns(host), sys.executable, *argv],
            capture_output=True,
            text=True,
            env=self.env if env is None else env,
            timeout=60,
        )

    def kill(self, procs: list[subprocess.Popen[str]]) -> None:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait(10)
            if proc.stdout is not None:
                proc.stdout.close()

    def close(self) -> None:
        """Kill what still runs, then delete the namespaces (their links go with them)."""
        self.kill(self.procs)
        for ns in reversed(self.created):
            subprocess.run(["ip", "netns", "delete", ns], capture_output=True, timeout=30)


def network(addresses: dict[str, str] | None = None, tag: str = "") -> Iterator[Hosts]:
    """Namespaces for `addresses` (host -> address in 10.77.0.0/24 or another /24) joined by a
    hub, whose processes hold a fleet key made for them (MIRO_KEYS); skips, saying why, where
    they cannot be made."""
    if not sys.platform.startswith("linux"):
        pytest.skip("network namespaces are a Linux feature")
    if os.geteuid() != 0:
        pytest.skip("creating network namespaces (ip netns add) needs root")
    if shutil.which("ip") is None:
        pytest.skip("the ip command (iproute2) is not installed")
    key = Path(tempfile.mkdtemp(prefix="miro-keys-")) / "fleet"
    made = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", "keys", "new", str(key)],
        capture_output=True,
        text=True,
        env=service_env(),
        timeout=60,
    )
    assert made.returncode == 0, made.stderr
    h = Hosts(Path(str(key) + ".key_secret"), addresses, tag)
    try:
        for host in ("hub", *h.addresses):
            done = h.add(host)
            if done.returncode != 0:
                pytest.skip(
                    f"ip netns add {h.ns(host)} failed: {done.stderr.strip()} "
                    "(a container without CAP_SYS_ADMIN?)"
                )
        h.link()
        yield h
    finally:
        h.close()
        shutil.rmtree(key.parent, ignore_errors=True)
