"""The GPS driver as a process on a pseudo-terminal, with a consumer of its readings: for the tests
and for bench/gps_captures.py."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

import Miro
from loopback import NamingProcess, Recorder, RunningServer, eventually, service_env

from miro_gen.sim.pty_device import PtyDevice

GPS = Path(__file__).resolve().parents[1] / "services" / "gps"
CONFIG = """<config><section name="Gps"><parameter name="Gps">
  <parameter name="Device" value="{device}"/>
  <parameter name="TtyParams"><parameter name="Baudrate" value="9600"/></parameter>
  <parameter name="WaitTimeout" value="2, 0"/>{extra}
</parameter></section></config>
"""


class Driver:
    """services/gps in a process of its own, in naming context "rover"; its log in a file."""

    def __init__(self, naming: str, device: Path, log: Path, **parameters: str) -> None:
        self.log = log
        self.stderr = log.open("w")
        config = log.with_name("rover.xml")  # the robot's run-time document
        extra = "".join(f'\n  <parameter name="{k}" value="{v}"/>' for k, v in parameters.items())
        config.write_text(CONFIG.format(device=device, extra=extra))
        self.proc = subprocess.Popen(
            [sys.executable, str(GPS), "-MCF", str(config), "--naming", naming,
             "-MNC", "rover", "-MLL", "5"],
            stdout=subprocess.PIPE,
            stderr=self.stderr,
            text=True,
            env=service_env(),
        )  # fmt: skip
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().startswith("gps: reading")

    def logged(self, text: str) -> int:
        return self.log.read_text().count(text)

    def stop(self) -> str:
        """Stop it (SIGINT); what it printed on the way out."""
        self.proc.send_signal(signal.SIGINT)
        out, _ = self.proc.communicate(timeout=20)
        self.stderr.close()
        return out

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.stderr.close()


class Rig:
    """A naming service, a pseudo-terminal, the driver on it and a consumer of its `Gps` events,
    subscribed before anything is sent (the driver logs when it sees the subscription)."""

    def __init__(self, tmp: Path, **parameters: str) -> None:
        self.naming = NamingProcess()
        self.device = PtyDevice(tmp / "gps0")
        self.driver = Driver(self.naming.endpoint, tmp / "gps0", tmp / "gps.log", **parameters)
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
            return self.driver.stop() if self.driver.proc.poll() is None else ""
        finally:
            self.driver.kill()
            self.gui.stop()
            self.device.close()
            self.naming.stop()
