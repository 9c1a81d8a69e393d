"""What an attacker of an IIOP server does, over raw sockets, and what is measured of the server
process meanwhile (shared by tests/corba/test_attack_iiop.py and bench/bench_iiop_floods.py).

The attacked process runs `VICTIM NOFILE SPARE`: an `IIOPServer` on 127.0.0.1 serving a
`Miro::Example` under the key `robot/Example`, with its file-descriptor limit lowered to NOFILE
(0: as it is) and, unless SPARE is -1, all descriptors but SPARE taken by other files, so that
`accept` soon fails with EMFILE. Its legitimate callers are `IIOPInvoker` stubs
(`calls_answered`).
"""

from __future__ import annotations

import contextlib
import os
import resource
import selectors
import signal
import socket
import struct
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from pathlib import Path

KEY = b"robot/Example"

VICTIM = """
import resource, sys, threading
import Miro, Miro__POA
from miro_gen.corba import IIOPInvoker, IIOPServer

class ExampleImpl(Miro__POA.Example):
    def __init__(self):
        self.value = Miro.ExampleStructIDL(1.0, 2.0)
    def getData(self):
        return self.value
    def setData(self, a, b):
        self.value = Miro.ExampleStructIDL(a, b)

nofile, spare = int(sys.argv[1]), int(sys.argv[2])
if nofile:
    hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, hard))
invoker = IIOPInvoker()
server = IIOPServer(invoker, "127.0.0.1", 0)
server.activate(ExampleImpl(), "robot/Example")
hog = []
while spare >= 0:  # other parts of the process hold all descriptors but `spare`
    try:
        hog.append(open("/dev/null"))
    except OSError:
        del hog[:spare]
        break
print(server.port, flush=True)
threading.Event().wait()
"""


class Victim:
    """`VICTIM` in a process of its own, from the source tree `root` (its `generated` and
    itself on the path), its warnings to `log` (a file; None: thrown away); `start_mib`: its
    resident memory once it serves."""

    def __init__(self, root: Path, nofile: int = 0, spare: int = -1, log: Path | None = None):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root / "generated"), str(root)]))
        with open(log or os.devnull, "w") as err:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", textwrap.dedent(VICTIM), str(nofile), str(spare)],
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
                env=env,
                cwd=str(root),
            )
        assert self.proc.stdout is not None
        self.port = int(self.proc.stdout.readline())
        self.pid = self.proc.pid
        time.sleep(0.5)  # the first connections' objects, the imports done
        self.start_mib = status(self.pid, "VmRSS") / 1024

    def added_mib(self) -> float:
        """Its peak resident memory beyond what it had when it started serving."""
        return peak_mib(self.pid) - self.start_mib

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


# ---- messages made by hand ----------------------------------------------------------------------


def request(
    request_id: int, size: int | None = None, *, more: bool = False, op: bytes = b"setData"
) -> bytes:
    """The first bytes of a GIOP 1.2 little-endian Request to `KEY` announcing `size` bytes
    after its 12-byte header (None: no body): the header and the request header (id, response
    expected, the key, the operation, no service contexts), padded to 8. The caller sends the
    rest."""
    head = struct.pack("<IB3xh2xI", request_id, 3, 0, len(KEY)) + KEY
    head += b"\0" * (-len(head) % 4) + struct.pack("<I", len(op) + 1) + op + b"\0"
    head += b"\0" * (-len(head) % 4) + struct.pack("<I", 0)
    head += b"\0" * (-(12 + len(head)) % 8)
    size = len(head) if size is None else size
    assert size >= len(head)
    flags = 1 | (2 if more else 0)
    return b"GIOP\x01\x02" + bytes((flags, 0)) + struct.pack("<I", size) + head


def fragment(request_id: int, data: bytes, *, more: bool) -> bytes:
    """A GIOP 1.2 Fragment of the request `request_id` carrying `data`."""
    flags = 1 | (2 if more else 0)
    return (
        b"GIOP\x01\x02"
        + bytes((flags, 7))
        + struct.pack("<I", 4 + len(data))
        + struct.pack("<I", request_id)
        + data
    )


# ---- floods -------------------------------------------------------------------------------------


def connect(port: int) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=60)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # an attacker reads nothing
    return s


def hold_big_requests(port: int, count: int, size: int) -> list[socket.socket]:
    """`count` connections, each sending a Request of `size` bytes all but its last byte, in
    parallel; they are held open (the caller closes them). A connection the server closes
    meanwhile is returned closed."""
    socks = [connect(port) for _ in range(count)]
    chunk = bytes(1 << 20)

    def send(s: socket.socket, n: int) -> None:
        first = request(n + 1, size)
        left = 12 + size - 1 - len(first)
        with contextlib.suppress(OSError):
            s.sendall(first)
            while left > 0:
                part = min(left, len(chunk))
                s.sendall(chunk[:part])
                left -= part

    threads = [threading.Thread(target=send, args=(s, n)) for n, s in enumerate(socks)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    return socks


def hold_fragments(port: int, requests: int, size: int, chunk: int = 1 << 20) -> socket.socket:
    """One connection sending `requests` fragmented Requests in turn, each a first part and
    fragments of `chunk` bytes up to `size`, never the last fragment. Returns the connection
    (closed if the server closed it)."""
    s = connect(port)
    data = bytes(chunk)
    try:
        for n in range(requests):
            rid = 1000 + n
            s.sendall(request(rid, more=True))
            for _ in range(size // chunk):
                s.sendall(fragment(rid, data, more=True))
    except OSError:
        s.close()
    return s


def open_idle(port: int, count: int, seconds: float = 30.0) -> list[socket.socket]:
    """`count` connections that send nothing (the caller closes them), opened 32 at a time
    with a pause between, so that a server that accepts them as they come finds none lost to
    its listening backlog; returns when all are established or after `seconds` (a server that
    accepts nothing leaves them waiting). Raises this process's descriptor limit first if it
    is too low for them."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < count + 256:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, count + 256), hard))
    socks = []
    end = time.monotonic() + seconds
    with selectors.DefaultSelector() as waiting:
        for n in range(count):
            s = socket.socket()
            s.setblocking(False)
            with contextlib.suppress(BlockingIOError):
                s.connect(("127.0.0.1", port))
            socks.append(s)
            waiting.register(s, selectors.EVENT_WRITE)
            if n % 32 == 31:
                time.sleep(0.05)
        while waiting.get_map() and time.monotonic() < end:
            for key, _ in waiting.select(0.5):
                waiting.unregister(key.fileobj)
    return socks


def close_all(socks: list[socket.socket]) -> None:
    for s in socks:
        with contextlib.suppress(OSError):
            s.close()


# ---- the server process, measured ---------------------------------------------------------------


def status(pid: int, field: str) -> int:
    """A number of /proc/PID/status (VmHWM, VmRSS in KiB; Threads)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise KeyError(field)


def peak_mib(pid: int) -> float:
    """The peak resident memory of `pid` so far (VmHWM), MiB."""
    return status(pid, "VmHWM") / 1024


def cpu_seconds(pid: int) -> float:
    """User and system CPU time `pid` has used so far."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def descriptors(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def settle(pid: int, seconds: float = 60.0) -> int:
    """Wait until the number of `pid`'s descriptors stays the same for 5 s (at most
    `seconds`): the connections a flood opened are then accepted, or never will be. Returns
    that number."""
    end = time.monotonic() + seconds
    last, same = -1, 0
    while time.monotonic() < end and same < 10:
        time.sleep(0.5)
        now = descriptors(pid)
        same = same + 1 if now == last else 0
        last = now
    return last


@contextlib.contextmanager
def cpu_share(pid: int) -> Iterator[list[float]]:
    """Measures the share of one CPU `pid` used during the block (put in the list)."""
    out: list[float] = []
    t0, c0 = time.monotonic(), cpu_seconds(pid)
    yield out
    out.append((cpu_seconds(pid) - c0) / (time.monotonic() - t0))


def calls_answered(port: int, calls: int, timeout: float = 10.0) -> tuple[int, list[str]]:
    """Make `calls` pairs of setData/getData calls to the victim, each on a new invoker (so a
    new connection); how many pairs were answered correctly, and the failures' messages."""
    import Miro

    from miro_gen.corba import IIOPInvoker
    from miro_gen.corba.ior import IOR, ref_from_ior

    ref = ref_from_ior(IOR.iiop(Miro.Example._repo_id, "127.0.0.1", port, KEY))
    ok, failures = 0, []
    for n in range(calls):
        invoker = IIOPInvoker()
        stub = Miro.Example(ref, invoker)
        stub._timeout = timeout
        try:
            stub.setData(float(n), 2.0)
            if stub.getData() == Miro.ExampleStructIDL(float(n), 2.0):
                ok += 1
        except Exception as e:
            failures.append(f"{type(e).__name__}: {e}")
        finally:
            invoker.close()
    return ok, failures
