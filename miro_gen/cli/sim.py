"""`miro sim KIND`: devices to run the drivers without hardware.

- `miro sim nmea`: a GPS receiver on a pseudo-terminal (services/gps);
- `miro sim scip`: a Hokuyo laser scanner on a pseudo-terminal or a TCP port (services/laser);
- `miro sim laser`: a laser scanner's events on a channel, no driver needed (cli/sim_laser.py);
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

from miro_gen.sim.nmea import recorded_epochs, sentences, synthetic_fixes
from miro_gen.sim.pty_device import PtyDevice


def _synthetic(args: argparse.Namespace) -> Iterator[tuple[float, list[bytes]]]:
    fixes = synthetic_fixes(
        time.time() // 1, rate=args.rate, speed=args.speed, noise=args.noise, seed=args.seed
    )
    for fix in fixes:
        yield 1.0 / args.rate, sentences(fix)


def _recorded(args: argparse.Namespace) -> Iterator[tuple[float, list[bytes]]]:
    while True:
        previous: float | None = None
        for when, lines in recorded_epochs(args.file):
            gap = 1.0 / args.rate
            if when is not None and previous is not None:
                gap = (when - previous) % 86400 or gap  # across midnight too
            previous = when if when is not None else previous
            yield gap, lines
        if not args.loop:
            return


def _stop_on_signals() -> threading.Event:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def nmea_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro sim nmea",
        description="Play a GPS receiver: NMEA 0183 (GGA, GSA, RMC, VTG) on a pseudo-terminal, "
        "at real-time rate, from a synthetic vehicle driving laps or from a recorded file. "
        "Prints the device to give the GPS driver.",
    )
    p.add_argument("--file", type=Path, help="replay this NMEA file instead of the vehicle")
    p.add_argument("--loop", action="store_true", help="replay the file again and again")
    p.add_argument("--rate", type=float, default=1.0, help="fixes per second (default 1)")
    p.add_argument("--speedup", type=float, default=1.0, help="play faster than real time")
    p.add_argument("--speed", type=float, default=5.0, help="vehicle speed, m/s (default 5)")
    p.add_argument("--noise", type=float, default=1.5, help="position noise, m (default 1.5)")
    p.add_argument("--seed", type=int, help="random seed, for a repeatable drive")
    p.add_argument("--link", type=Path, help="also reach the device at this path (a symlink)")
    p.add_argument("--duration", type=float, default=0, help="stop after S seconds")
    p.add_argument("--output", type=Path, help="write N seconds of NMEA to a file and exit")
    args = p.parse_args(argv)
    if args.rate <= 0 or args.speedup <= 0 or args.duration < 0:
        p.error("--rate and --speedup must be more than 0, --duration at least 0")
    if args.file is not None and not args.file.is_file():
        p.error(f"{args.file}: no such file")
    epochs = _recorded(args) if args.file else _synthetic(args)

    if args.output is not None:
        if not args.duration:
            p.error("--output needs --duration (seconds of NMEA to write)")
        written = 0.0
        with args.output.open("wb") as out:
            for gap, lines in epochs:
                if written >= args.duration:
                    break
                out.write(b"".join(lines))
                written += gap
        return 0

    stop = _stop_on_signals()
    try:
        device = PtyDevice(args.link)
    except OSError as e:
        print(f"miro sim: cannot create the device: {e}", file=sys.stderr)
        return 1
    print(f"NMEA on {device.path} (Ctrl-C to stop)", flush=True)
    sent = 0
    start = due = time.monotonic()
    end = start + args.duration if args.duration else float("inf")
    try:
        for gap, lines in epochs:
            if stop.wait(max(0.0, due - time.monotonic())) or due >= end:
                break
            device.write(b"".join(lines))
            sent += 1
            due += gap / args.speedup
    finally:
        device.close()
    lost = f", {device.dropped} bytes nobody read" if device.dropped else ""
    print(f"sent {sent} epochs{lost}", flush=True)
    return 0


def scip_main(argv: Sequence[str]) -> int:
    from miro_gen.devices.scip import MODELS
    from miro_gen.sim.scip import Faults, PtyLink, ScipDevice, ScipServer, TcpLink, make_scene

    p = argparse.ArgumentParser(
        prog="miro sim scip",
        description="Play a Hokuyo laser scanner speaking SCIP 2.0 (VV, PP, II, BM, QT, GD/GS, "
        "MD/MS) on a pseudo-terminal (as a USB scanner) or a TCP port (as an Ethernet one), "
        "scanning a room with a moving pillar or replaying recorded scans. Prints where it is.",
    )
    p.add_argument("--model", choices=sorted(MODELS), default="URG-04LX", help="default URG-04LX")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--link", type=Path, help="also reach the terminal at this path (a symlink)")
    where.add_argument("--tcp", type=int, metavar="PORT", help="listen on this TCP port (0: any)")
    p.add_argument(
        "--scene",
        type=Path,
        help="replay these scans: a text file (a scan per line, millimetres) or an MCAP log of "
        "RangeScanEventIDL events",
    )
    p.add_argument(
        "--split", type=int, default=0, metavar="N", help="write in pieces of 1 to N bytes"
    )
    for fault, what in (
        ("corrupt", "with a wrong checksum"),
        ("truncate", "cut short"),
        ("repeat", "followed by an old scan again"),
    ):
        p.add_argument(
            f"--{fault}", type=int, default=0, metavar="N", help=f"every Nth scan {what}"
        )
    p.add_argument("--duration", type=float, default=0, help="stop after S seconds")
    p.add_argument("--seed", type=int, default=0, help="for --split's random pieces")
    args = p.parse_args(argv)
    if min(args.split, args.corrupt, args.truncate, args.repeat, args.duration) < 0:
        p.error("--split, --corrupt, --truncate, --repeat and --duration must not be negative")
    try:
        scene = make_scene(args.scene)
    except (OSError, ValueError) as e:
        print(f"miro sim: {e}", file=sys.stderr)
        return 1
    faults = Faults(args.corrupt, args.truncate, args.repeat)
    device = ScipDevice(MODELS[args.model], scene, faults=faults)
    stop = _stop_on_signals()
    try:
        link: PtyLink | TcpLink = TcpLink(args.tcp) if args.tcp is not None else PtyLink(args.link)
    except OSError as e:
        print(f"miro sim: cannot create the device: {e}", file=sys.stderr)
        return 1
    print(f"SCIP 2.0 ({args.model}) on {link.path} (Ctrl-C to stop)", flush=True)
    server = ScipServer(device, link, split=args.split, seed=args.seed)
    end = time.monotonic() + args.duration if args.duration else float("inf")
    try:
        server.run(until=lambda: stop.is_set() or time.monotonic() >= end)
    finally:
        link.close()
    sent = ", ".join(f"{n} {k}" for k, n in faults.sent.items() if n)
    print(f"sent {device.scans} scans{' (' + sent + ')' if sent else ''}", flush=True)
    return 0


def camera_main(argv: Sequence[str]) -> int:
    p = argparse.ArgumentParser(
        prog="miro sim camera",
        description="Play a camera: a synthetic video (a disc circling over a gradient, each "
        "frame's number in a bar code at the top left) written to a file (Motion JPEG in .avi, "
        "MPEG-4 in .mp4) or served as an MJPEG stream over HTTP, as IP cameras serve it. "
        "Needs OpenCV (pip install 'miro-gen[camera]').",
    )
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("--output", type=Path, help="write the video to this file and exit")
    out.add_argument("--http", type=int, metavar="PORT", help="serve it on this port (0: any)")
    p.add_argument("--width", type=int, default=1280, help="pixels (default 1280)")
    p.add_argument("--height", type=int, default=720, help="pixels (default 720)")
    p.add_argument("--rate", type=float, default=30.0, help="frames a second (default 30)")
    p.add_argument("--frames", type=int, default=300, help="frames to write (default 300)")
    p.add_argument("--duration", type=float, default=0, help="stop serving after S seconds")
    args = p.parse_args(argv)
    if min(args.width, args.height, args.frames) <= 0 or args.rate <= 0 or args.duration < 0:
        p.error("--width, --height, --frames and --rate must be more than 0")
    try:
        from miro_gen.sim import camera
    except ImportError as e:
        print(f"miro sim: needs OpenCV ({e}): pip install 'miro-gen[camera]'", file=sys.stderr)
        return 1
    if args.output is not None:
        try:
            camera.write_video(args.output, args.frames, args.width, args.height, args.rate)
        except OSError as e:
            print(f"miro sim: {e}", file=sys.stderr)
            return 1
        print(f"wrote {args.frames} frames of {args.width}x{args.height} to {args.output}")
        return 0
    stop = _stop_on_signals()
    try:
        stream = camera.MjpegStream(args.width, args.height, args.rate, args.http)
    except OSError as e:
        print(f"miro sim: cannot serve on port {args.http}: {e}", file=sys.stderr)
        return 1
    stream.serve()
    print(f"MJPEG on {stream.url} (Ctrl-C to stop)", flush=True)
    stop.wait(args.duration or None)
    stream.close()
    print(f"sent {stream.sent} frames", flush=True)
    return 0
