"""Device drivers (services/gps, services/laser, services/camera) as processes, with consumers of
their events: for the tests and for bench/."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

import Miro
from loopback import NamingProcess, Recorder, RunningServer, eventually, service_env

from miro_gen.sim.pty_device import PtyDevice

SERVICES = Path(__file__).resolve().parents[1] / "services"
GPS = SERVICES / "gps"


class Driver:
    """services/NAME in a process of its own, in naming context "rover", its parameters in a
    run-time document (section and category `category`); its log in a file."""

    def __init__(
        self, name: str, category: str, naming: str, log: Path, **parameters: object
    ) -> None:
        self.name = name
        self.log = log
        self.stderr = log.open("w")
        config = log.with_name(f"{name}-rover.xml")  # the robot's run-time document
        config.write_text(
            f'<config><section name="{category}"><parameter name="{category}">'
            + "".join(_parameter(k, v) for k, v in parameters.items())
            + "</parameter></section></config>\n"
        )
        self.proc = subprocess.Popen(
            [sys.executable, str(SERVICES / name), "-MCF", str(config), "--naming", naming,
             "-MNC", "rover", "-MLL", "5"],
            stdout=subprocess.PIPE,
            stderr=self.stderr,
            text=True,
            env=service_env(),
        )  # fmt: skip
        assert self.proc.stdout is not None
        first = self.proc.stdout.readline()
        assert first.startswith(f"{name}: reading"), first + log.read_text()

    def logged(self, text: str) -> int:
        return self.log.read_text().count(text)

    def stop(self, events: Recorder | None = None) -> str:
        """Stop it (SIGINT); what it printed on the way out. With `events`, its consumer, also
        wait until that has received all the driver says it published (`N published`)."""
        self.proc.send_signal(signal.SIGINT)
        out, _ = self.proc.communicate(timeout=20)
        self.stderr.close()
        published = re.search(r"(\d+) published", out)
        if events is not None and published is not None:
            eventually(lambda: len(events.events) >= int(published[1]), 30)
        return out

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.stderr.close()


def _parameter(name: str, value: object) -> str:
    """A run-time document's <parameter>: a value, or a structure given as a dict."""
    if isinstance(value, dict):
        inner = "".join(_parameter(k, v) for k, v in value.items())
        return f'<parameter name="{name}">{inner}</parameter>'
    return f'<parameter name="{name}" value="{value}"/>'


class GpsRig:
    """A naming service, a pseudo-terminal, the driver on it and a consumer of its `Gps` events,
    subscribed before anything is sent (the driver logs when it sees the subscription)."""

    def __init__(self, tmp: Path, **parameters: str) -> None:
        self.naming = NamingProcess()
        self.device = PtyDevice(tmp / "gps0")
        settings = {"Device": tmp / "gps0", "TtyParams": {"Baudrate": 9600}, "WaitTimeout": "2, 0"}
        self.driver = Driver(
            "gps", "Gps", self.naming.endpoint, tmp / "gps.log", **settings, **parameters
        )
        self.gui = RunningServer(self.naming.endpoint, "gui")
        self.events = Recorder(self.gui.server.resolve_channel("rover/EventChannel"))
        self.events.set_subscriptions([("rover", "Gps")])
        self.closed = False
        eventually(lambda: self.driver.logged("receiver connected") == 1)
        eventually(lambda: self.driver.logged("someone subscribes") == 1)

    def readings(self) -> list[Miro.GpsDataIDL]:
        return [e.payload for e in self.events.events]  # type: ignore[misc]

    def replay(self, lines: Iterable[bytes], settle: float = 1.0) -> list[Miro.GpsDataIDL]:
        """Write `lines` to the terminal as fast as the driver reads them, losing none; then
        wait until no reading has come for `settle` seconds (the driver completes the last fix
        after a quarter of a second of silence). All readings received so far."""
        for line in lines:
            self.device.write(line, wait=10.0)
        assert self.device.dropped == 0
        count, quiet_since = -1, time.monotonic()
        while time.monotonic() - quiet_since < settle:
            if len(self.events.events) != count:
                count, quiet_since = len(self.events.events), time.monotonic()
            time.sleep(0.05)
        return self.readings()

    def close(self) -> str:
        """Stop everything (once); the driver's closing summary."""
        if self.closed:
            return ""
        self.closed = True
        try:
            return self.driver.stop(self.events) if self.driver.proc.poll() is None else ""
        finally:
            self.driver.kill()
            self.gui.stop()
            self.device.close()
            self.naming.stop()
