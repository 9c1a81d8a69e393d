"""Servers of ExampleA's servant made by forking one that has done its imports (as a zygote does),
so that a test can kill a server outright and start it again many times over without paying
Python's start-up each time.

    python tests/procs/standby_example.py [common options] NAME

Commands on its standard input, answers on its standard output (one line each, N a number the
test picks):

    SPAWN N  ->  PID N <pid>, then STANDBY N once server N has made its Server (its own
                 process, a fork of this one, with no ZeroMQ context before the fork)
    GO N     ->  READY N once server N has bound NAME (taking it over from the run before, as
                 any restart does) and serves
    GO N S   ->  the same, server N letting the calls it serves take S seconds to finish
                 when it stops (its drain_timeout; 2 by default)

A server's setData(a, b) with a < 0 prints BUSY N and sleeps -a seconds first. A server ends on
SIGINT/SIGTERM (unbinding NAME) or SIGKILL, and with this process (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]

import Miro  # noqa: E402
import Miro__POA  # noqa: E402

from miro_gen import Server  # noqa: E402

PR_SET_PDEATHSIG = 1


def say(text: str) -> None:
    os.write(1, f"{text}\n".encode())  # one write: lines of several processes do not mix


class Example(Miro__POA.Example):
    def __init__(self, number: str) -> None:
        self.number = number
        self.data = Miro.ExampleStructIDL()

    def setData(self, a: float, b: float) -> None:
        if a < 0:
            say(f"BUSY {self.number}")
            time.sleep(-a)
        self.data = Miro.ExampleStructIDL(a, b)

    def getData(self) -> Miro.ExampleStructIDL:
        return Miro.ExampleStructIDL(self.data.a + 1, self.data.b + 1)


def serve(number: str, go: int) -> None:
    """Server `number` (a forked child): made now, bound when its pipe says GO."""
    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    server = Server(sys.argv)
    say(f"STANDBY {number}")
    command, *drain = os.read(go, 64).split()
    if command != b"GO":
        os._exit(0)
    if drain:
        server.drain_timeout = float(drain[0])
    server.add_to_name_service(Example(number), sys.argv[1])
    server.reactor().call_soon(lambda: say(f"READY {number}"))
    server.run()
    sys.exit(0)  # not os._exit: the replies sent while stopping still leave


def main() -> None:
    pipes: dict[str, int] = {}
    for line in sys.stdin:
        command, _, number = line.strip().partition(" ")
        if command == "SPAWN":
            read, write = os.pipe()
            pid = os.fork()
            if pid == 0:
                os.close(write)
                serve(number, read)
            os.close(read)
            pipes[number] = write
            say(f"PID {number} {pid}")
        elif command == "GO":
            number, _, drain = number.partition(" ")
            os.write(pipes.pop(number), f"GO {drain}".encode())


if __name__ == "__main__":
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # children reaped as they end
    main()
