"""`miro log player [FILE...]`: the player's window (miro_gen.qt.logplayer), with the `qt`
extra: the same file set, channels and options as `miro log play`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from miro_gen.cli.eventargs import COMMON, make_server, split_common
from miro_gen.cli.log_play import (
    add_channel_options,
    add_selection_options,
    apply_selection,
    channel_mode,
    check_selection,
)


def player_main(argv: Sequence[str]) -> int:
    prog = "miro log player"
    p = argparse.ArgumentParser(
        prog=prog,
        description="Miro's LogPlayer window: play logs (merged in log-time order; more opened "
        "and closed from the File menu) into each robot's channel; pause, stop, step both "
        "ways, seek on the slider or the timeline, change the speed, cut and save the cut, "
        "leave topics out, list the events sent, and look at any event (its fields, images, "
        "range scans, plots of its numbers). Needs the qt extra (PySide6). " + COMMON,
    )
    p.add_argument("files", nargs="*", metavar="FILE", help="MCAP files to open")
    add_channel_options(p)
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    p.add_argument("--loop", action="store_true", help="start again at the end")
    p.add_argument("--play", action="store_true", help="start playing at once")
    p.add_argument(
        "--history", type=int, default=100, metavar="N", help="events in the event list (100)"
    )
    add_selection_options(p)
    ns = p.parse_args(split_common(p, argv))
    if not ns.rate > 0:
        p.error("--rate must be more than 0")
    if not 1 <= ns.history <= 100_000:
        p.error("--history is 1 to 100000 events")
    check_selection(p, ns)
    try:
        from miro_gen.qt.app import application, no_display
    except ImportError as e:
        hint = "" if "miro-gen[qt]" in str(e) else ": pip install miro-gen[qt]"
        print(f"{prog}: {e}{hint}", file=sys.stderr)
        return 1
    problem = no_display()
    if problem is not None:
        print(f"{prog}: {problem}", file=sys.stderr)
        return 1
    from miro_gen.eventlog.fileset import FileSet
    from miro_gen.eventlog.player import Player, pace_process
    from miro_gen.eventlog.routes import ClockPublisher, Routes
    from miro_gen.exceptions import SystemException
    from miro_gen.qt.bridge import QtEventBridge
    from miro_gen.qt.logplayer import LogPlayerWindow

    app = application("miro log player")
    server = make_server(p, prog, argv)
    routes = Routes(server, ns.channel, channel_mode(ns))
    try:
        clock = ClockPublisher(server, ns.clock_channel)
    except SystemException as e:
        print(f"{prog}: {server.options.naming}: {e}", file=sys.stderr)
        server.close()
        return 1
    files = FileSet()
    player = Player(files, routes.send, clock, rate=ns.rate, loop=ns.loop, history=ns.history)
    window = LogPlayerWindow(player, routes)
    bridge = QtEventBridge(server, window=window)
    bridge.start()
    pace_process()  # replayed events leave on time (miro log play)
    player.start()
    window.resize(1280, 800)
    window.show()
    window.open_files(ns.files)
    for line in apply_selection(files, ns):
        window.warn(line)
    if ns.play:
        player.play()
    try:
        app.exec()
    finally:
        player.close()
        bridge.stop()
        files.close()
    return 0
