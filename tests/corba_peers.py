"""What the CORBA interoperability tests share: omniNames on a free port, the C++ omniORB peer
(tests/corba/peer.cc, built once with omniidl and g++ and cached by the hash of its sources),
the Python stubs of tests/corba/Peer.idl, and a Python servant of `Peer::Echo` that behaves as
the C++ one does."""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from loopback import free_port, service_env
from miro_cli import REPO

CORBA = REPO / "tests" / "corba"
COS_IDL = Path("/usr/share/idl/omniORB")
COS_HEADERS = Path("/usr/include/COS")
NEEDED = ("omniNames", "omniidl", "g++")


def missing_tools() -> list[str]:
    """The programs the CORBA tests need that this machine lacks (.ci/run installs them)."""
    missing = [t for t in NEEDED if shutil.which(t) is None]
    if not (COS_IDL / "COS" / "CosEventChannelAdmin.idl").is_file():
        missing.append("omniorb-idl")
    if not Path("/usr/include/omniORB4/CORBA.h").is_file():
        missing.append("libomniorb4-dev")
    return missing


def build_peer() -> Path:
    """The C++ peer, built from Peer.idl, peer.cc and omniORB's CosEvent IDL (once per source
    version: the build lands in the temporary folder under the hash of its inputs)."""
    sources = [CORBA / "Peer.idl", CORBA / "peer.cc"]
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()[:16]
    out = Path(tempfile.gettempdir()) / f"miro-corba-peer-{digest}"
    binary = out / "peer"
    if binary.is_file():
        return binary
    work = Path(tempfile.mkdtemp(prefix="miro-corba-build-"))
    (work / "COS_sysdep.h").write_text("")
    idls = [
        CORBA / "Peer.idl",
        COS_IDL / "COS/CosEventComm.idl",
        COS_IDL / "COS/CosEventChannelAdmin.idl",
    ]
    for idl in idls:
        subprocess.run(
            ["omniidl", "-bcxx", "-Wba", f"-I{COS_IDL}/COS", f"-I{COS_IDL}", str(idl)],
            cwd=work, check=True, capture_output=True, timeout=120,
        )  # fmt: skip
    stubs = sorted(str(p) for p in work.glob("*SK.cc"))
    proc = subprocess.run(
        ["g++", "-O1", "-I.", "-o", "peer", str(CORBA / "peer.cc"), *stubs,
         "-lomniORB4", "-lomniDynamic4", "-lomnithread", "-lpthread"],
        cwd=work, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-4000:]
    out.mkdir(exist_ok=True)
    os.replace(work / "peer", binary)
    shutil.rmtree(work, ignore_errors=True)
    return binary


MIRO_IDL = ("Time", "Exception", "Gps", "RangeEvent")  # what notify_peer.cc uses of idl/


def build_notify_peer() -> Path:
    """The C++ CosNotification peer (tests/corba/notify_peer.cc) built against omniORB's
    CosNotify stubs (libCOS4) and omniidl's stubs of the project's Miro IDL and of
    NotifyBench.idl (once per source version, cached under the hash of its inputs)."""
    sources = [CORBA / "notify_peer.cc", CORBA / "NotifyBench.idl"]
    sources += [REPO / "idl" / f"{name}.idl" for name in MIRO_IDL]
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()[:16]
    out = Path(tempfile.gettempdir()) / f"miro-notify-peer-{digest}"
    binary = out / "notify_peer"
    if binary.is_file():
        return binary
    work = Path(tempfile.mkdtemp(prefix="miro-notify-build-"))
    for idl in sources[1:]:
        subprocess.run(
            ["omniidl", "-bcxx", "-Wba", f"-I{REPO / 'idl'}", str(idl)],
            cwd=work, check=True, capture_output=True, timeout=120,
        )  # fmt: skip
    stubs = sorted(str(p) for p in work.glob("*SK.cc"))
    proc = subprocess.run(
        ["g++", "-O1", "-I.", f"-I{COS_HEADERS}", "-o", "notify_peer", str(sources[0]), *stubs,
         "-lCOS4", "-lomniDynamic4", "-lomniORB4", "-lomnithread", "-lpthread"],
        cwd=work, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-4000:]
    out.mkdir(exist_ok=True)
    os.replace(work / "notify_peer", binary)
    shutil.rmtree(work, ignore_errors=True)
    return binary


def notify_tools_missing() -> list[str]:
    """What the CosNotification tests need beyond the CORBA tests' tools: omniORB's CosNotify
    stubs and headers (libcos4-dev) and nameclt."""
    missing = missing_tools()
    if not (COS_HEADERS / "CosNotifyChannelAdmin.hh").is_file():
        missing.append("libcos4-dev")
    if shutil.which("nameclt") is None:
        missing.append("omniorb (nameclt)")
    return missing


def generate_python(out: Path) -> None:
    """The Python packages Peer and Peer__POA, generated from Peer.idl into `out`."""
    proc = subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.idl", "-o", str(out), str(CORBA / "Peer.idl")],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr


@contextlib.contextmanager
def peer_types(out: Path) -> Iterator[SimpleNamespace]:
    """Peer and Peer__POA generated into `out` and imported (`.Peer`, `.POA`, `.path`), for
    the time of a test module."""
    generate_python(out)
    sys.path.insert(0, str(out))
    try:
        yield SimpleNamespace(
            Peer=importlib.import_module("Peer"), POA=importlib.import_module("Peer__POA"), path=out
        )
    finally:
        sys.path.remove(str(out))
        for name in [m for m in sys.modules if m.split(".")[0] in ("Peer", "Peer__POA")]:
            del sys.modules[name]


@contextlib.contextmanager
def running_omninames() -> Iterator[OmniNames]:
    names = OmniNames()
    try:
        yield names
    finally:
        names.stop()


class OmniNames:
    """omniNames on a free port of 127.0.0.1 (never 2809), its data in a temporary folder."""

    def __init__(self) -> None:
        self.port = free_port()
        self.dir = tempfile.mkdtemp(prefix="miro-omninames-")
        self.url = f"corbaloc::127.0.0.1:{self.port}/NameService"
        self.proc = subprocess.Popen(
            ["omniNames", "-start", str(self.port), "-datadir", self.dir, "-logdir", self.dir],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        wait_giop("127.0.0.1", self.port)

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait(10)
        shutil.rmtree(self.dir, ignore_errors=True)


def wait_giop(host: str, port: int, timeout: float = 20.0) -> None:
    from miro_gen.corba.naming import Peer, probe

    deadline = time.monotonic() + timeout
    while probe(host, port, timeout=0.5) != Peer.GIOP:
        assert time.monotonic() < deadline, f"nothing speaks GIOP at {host}:{port}"
        time.sleep(0.05)


class CppPeer:
    """The C++ peer in a process of its own: `peer MODE NAME [N] ORB-OPTIONS`. A server
    prints `READY <IOR>` and serves until its standard input closes."""

    def __init__(self, binary: Path, mode: str, name: str, *args: str, naming: str = "") -> None:
        cmd = [str(binary), mode, name, *args]
        if naming:
            cmd += ["-ORBInitRef", f"NameService={naming}"]
        self.proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True,
        )  # fmt: skip
        self.ior = ""

    def ready(self, timeout: float = 20.0) -> str:
        """Wait for a server's READY line; its IOR."""
        line = self.readline(timeout)
        assert line.startswith("READY "), line
        self.ior = line.split()[1]
        return self.ior

    def readline(self, timeout: float = 20.0) -> str:
        assert self.proc.stdout is not None
        return readline(self.proc.stdout, timeout, "the C++ peer")

    def finish(self, timeout: float = 60.0) -> tuple[int, str]:
        """Close its input, wait for the end; its exit status and output."""
        out, _ = self.proc.communicate(timeout=timeout)
        return self.proc.returncode, out

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.communicate(timeout=10)


def readline(stream: Any, timeout: float, who: str) -> str:
    """The next line of `stream`, stripped; fails when none comes within `timeout`."""
    result: list[str] = []
    reader = threading.Thread(target=lambda: result.append(stream.readline()), daemon=True)
    reader.start()
    reader.join(timeout)
    assert result, f"{who} said nothing in time"
    return result[0].strip()


def run_peer(
    binary: Path, mode: str, name: str, *args: str, naming: str = "", timeout: float = 60.0
) -> tuple[int, str]:
    peer = CppPeer(binary, mode, name, *args, naming=naming)
    try:
        return peer.finish(timeout)
    finally:
        peer.kill()


def python_env() -> dict[str, str]:
    return service_env()


def echo_servant(Peer: Any, Peer__POA: Any) -> Any:
    """A Python servant of Peer::Echo behaving as the C++ one (tests/corba/peer.cc)."""
    from miro_gen import BAD_PARAM, CompletionStatus, nonblocking
    from miro_gen.corba import CORBA_SYSTEM_EXCEPTIONS

    class Echo(Peer__POA.Echo):  # type: ignore[misc, name-defined]
        def __init__(self) -> None:
            self.total = 0
            self.counter = 0

        def echo_prims(self, p: Any) -> Any:
            return p

        def echo_nested(self, n: Any) -> Any:
            return n

        def echo_nesteds(self, n: Any) -> Any:
            return n

        @nonblocking
        def echo_text(self, s: str) -> str:
            return s

        def echo_longs(self, s: Any) -> Any:
            return s

        def echo_doubles(self, d: Any) -> Any:
            return d

        def echo_octets(self, o: bytes) -> bytes:
            return o

        def echo_strings(self, s: Any) -> Any:
            return s

        def echo_shape(self, s: Any) -> Any:
            return s

        def echo_pick(self, p: Any) -> Any:
            return p

        def echo_color(self, c: Any) -> Any:
            return c

        def mixed(self, a: int, p: Any, m: Any) -> Any:
            moved = Peer.Point(p.x + 1, p.y + 1)
            return a / 4, 2 * a, f"a={a}", moved, [[v * 10 for v in row] for row in m]

        @nonblocking
        def nothing(self) -> None:
            pass

        def raise_it(self, which: int) -> None:
            if which == 0:
                raise Peer.Failed("bad", 42, 2.5)
            if which == 1:
                raise Peer.Empty()
            if which == 2:
                raise BAD_PARAM("refused", 7, CompletionStatus.NO)
            if which == 3:
                raise CORBA_SYSTEM_EXCEPTIONS["NO_PERMISSION"]("no", 5, CompletionStatus.YES)
            if which == 4:
                raise RuntimeError("a bug in the servant")

        def fire(self, v: int) -> None:
            self.total += v

        def fired(self) -> int:
            return self.total

        def myself(self) -> Any:
            return self

        def call_back(self, cb: Any, what: str) -> str:
            return str(cb.notify(what))

        def echo_object(self, o: Any) -> Any:
            return o

        def echo_callbacks(self, cbs: list[Any]) -> list[Any]:
            return cbs

        def swap_echo(self, e: Any) -> Any:
            return self

        def _get_counter(self) -> int:
            return self.counter

        def _set_counter(self, c: int) -> None:
            self.counter = c

        def _get_label(self) -> str:
            return "python"

    return Echo()
