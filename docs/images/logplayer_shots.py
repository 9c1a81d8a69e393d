"""Takes the screenshots of the player window in docs/LOGS.md (docs/images/logplayer-*.png).

    python docs/images/logplayer_shots.py [--out docs/images]

Writes two robots' logs (robot1: odometry along a circle, a 361-beam laser scan of the
simulated room, camera images; robot2: odometry), opens them in the window offscreen
(QT_QPA_PLATFORM=offscreen; no naming service: the events go nowhere), plays a while at x4,
cuts, plots a field, and grabs the window with the inspector on each kind of view.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "generated"), str(ROOT)]
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import Miro  # noqa: E402
from PySide6.QtWidgets import QApplication  # noqa: E402

from miro_gen.eventlog.fileset import FileSet  # noqa: E402
from miro_gen.eventlog.player import Player  # noqa: E402
from miro_gen.eventlog.writer import LogWriter  # noqa: E402
from miro_gen.qt.logplayer import LogPlayerWindow  # noqa: E402
from miro_gen.sim.laser import LaserScans  # noqa: E402
from miro_gen.transport.events.frames import RawEvent  # noqa: E402

T0 = 1_764_000_000_000_000_000  # a morning in November 2025
SECONDS = 30


def event(domain: str, type_name: str, payload: object, seq: int, t: int) -> RawEvent:
    cls = type(payload)
    data = payload.serialize()  # type: ignore[attr-defined]
    return RawEvent(domain, type_name, cls._type_hash, 1, seq, t, t, data)  # type: ignore[attr-defined]


def odometry(t: float, radius: float, speed: float) -> Miro.MotionStatusIDL:
    a = speed * t / radius
    pos = Miro.PositionIDL(
        Miro.WorldPointIDL(radius * math.cos(a), radius * math.sin(a)), a + math.pi / 2
    )
    return Miro.MotionStatusIDL(
        Miro.TimeIDL(int(t), 0), pos, Miro.VelocityIDL(int(speed), speed / radius)
    )


def image(n: int) -> Miro.ImageEventIDL:
    w, h = 160, 120
    rows = bytearray()
    for y in range(h):
        for x in range(w):
            rows += bytes(((x * 2 + n * 4) % 256, (y * 2) % 256, (x + y + n * 8) % 256))
    fmt = Miro.ImageFormatIDL(w, h, Miro.ImageEncodingIDL.IMAGE_RGB8, w * 3)
    return Miro.ImageEventIDL(Miro.TimeIDL(), n, fmt, bytes(rows))


def write_logs(folder: Path) -> list[Path]:
    robot1, robot2 = folder / "robot1.mcap", folder / "robot2.mcap"
    scans = LaserScans(beams=361, rate=10.0)
    w1 = LogWriter(str(robot1))
    w2 = LogWriter(str(robot2))
    for n in range(SECONDS * 10):
        t = T0 + n * 100_000_000
        s = n / 10
        w1.write([event("robot1", "Odometry", odometry(s, 2000, 300), n, t)], t)
        w1.write(
            [
                event(
                    "robot1",
                    "Laser",
                    Miro.RangeScanEventIDL(Miro.TimeIDL(), [scans.scan(n)]),
                    n,
                    t + 10_000_000,
                )
            ],
            t + 10_000_000,
        )
        if n % 2 == 0:
            w1.write(
                [event("robot1", "Image", image(n // 2), n // 2, t + 20_000_000)], t + 20_000_000
            )
        w2.write(
            [event("robot2", "Odometry", odometry(s, 3500, 450), n, t + 50_000_000)], t + 50_000_000
        )
    w1.finish()
    w2.finish()
    return [robot1, robot2]


def settle(app: QApplication, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        app.processEvents()
        time.sleep(0.01)


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    args = ap.parse_args()
    app = QApplication(["miro log player"])
    with tempfile.TemporaryDirectory() as tmp:
        files = FileSet()
        player = Player(files, lambda event: None, rate=4.0)
        window = LogPlayerWindow(player)
        window.resize(1280, 800)
        window.show()
        window.open_files([str(p) for p in write_logs(Path(tmp))])
        player.start()
        player.play()
        while player.log_now() < T0 + 14 * 10**9:
            settle(app, 0.05)
        player.pause()
        files.cut_back(T0 + 26 * 10**9)
        window.set_history(100)
        inspector = window.inspector
        inspector.choose_topic(("robot1", "Odometry"))
        settle(app, 0.3)
        inspector.over.setCurrentIndex(0)
        inspector.plot_field("position.point.x")
        settle(app, 1.5)
        shots = []
        for name, topic in (
            ("logplayer-window.png", ("robot1", "Odometry")),
            ("logplayer-laser.png", ("robot1", "Laser")),
            ("logplayer-image.png", ("robot1", "Image")),
        ):
            inspector.choose_topic(topic)
            settle(app, 1.5)
            path = args.out / name
            if not window.grab().save(str(path), "PNG"):
                print(f"cannot write {path}", file=sys.stderr)
                return 1
            shots.append(path)
        player.close()
        window.close()
        files.close()
    for path in shots:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
