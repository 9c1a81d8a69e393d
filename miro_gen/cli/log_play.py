"""`miro log play`: Miro's LogPlayer on the terminal, replaying MCAP files (merged in log-time
order) into each robot's channel; and what it shares with the player window (`miro log
player`): opening the files, the cut and topic options, the channel options."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from miro_gen.cli.eventargs import COMMON, make_server, split_common, topic_arg
from miro_gen.foxglove import DEFAULT_PORT as FOXGLOVE_PORT

if TYPE_CHECKING:
    from miro_gen.eventlog.routes import Routes

KEYS = (
    "On a terminal: space pauses and resumes, s (or right) sends the next event, p (or left) "
    "the one before, shift+left/right (or [ and ]) seek a 20th of the log, + and - change the "
    "speed, 0 goes back to the start, q quits."
)


def add_selection_options(p: argparse.ArgumentParser) -> None:
    """--start/--end (the cut) and --topics/--exclude, as play, player and cut take them."""
    p.add_argument("--start", type=float, default=0.0, metavar="S", help="from S s into the log")
    p.add_argument("--end", type=float, metavar="E", help="up to E s into the log")
    p.add_argument(
        "--topics", nargs="+", type=topic_arg, metavar="TOPIC", help="DOMAIN/TYPE (default all)"
    )
    p.add_argument(
        "--exclude", nargs="+", type=topic_arg, default=[], metavar="TOPIC", help="leave out"
    )


def add_channel_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--channel",
        default="EventChannel",
        metavar="NAME",
        help="the channels' name: each robot's events go into the channel its services find "
        "(ROBOT/NAME, else NAME at the root), hosted and bound as ROBOT/NAME where there is "
        "none; a path (lab/EventChannel) sends everything into that one (default EventChannel)",
    )
    modes = p.add_mutually_exclusive_group()
    modes.add_argument(
        "--shared-channels",
        action="store_true",
        help="only the channels that exist: a robot without one is not played (Miro's -shared_ec)",
    )
    modes.add_argument(
        "--unified-channel",
        action="store_true",
        help="one channel for all the robots, hosted here and bound as ROBOT/NAME for each "
        "(Miro's -unified_ec)",
    )
    p.add_argument(
        "--clock-channel",
        default="LogClock",
        metavar="NAME",
        help="the channel, hosted here, where the log clock is published for processes on "
        "--clock log (default LogClock)",
    )


def check_selection(p: argparse.ArgumentParser, ns: Any) -> None:
    if ns.start < 0 or (ns.end is not None and ns.end < ns.start):
        p.error("--start must be 0 or more, and --end not before it")


def open_files(paths: Sequence[str], files: Any, strict: bool) -> bool:
    """Open each log into the file set, a progress line while one is scanned; False (and
    said) when one cannot be read, or, `strict`, has a fault."""
    from miro_gen.eventlog.progress import StatusLine, bar
    from miro_gen.eventlog.reader import LogError

    for path in paths:
        status = StatusLine()

        def progress(fraction: float, path: str = path, status: StatusLine = status) -> bool:
            status.update(f"{path}: no index, reading it through {bar(fraction)}")
            return True

        try:
            log = files.add(path, progress)
        except LogError as e:
            status.done(f"{path}: error: {e}")
            return False
        if log.fault is not None:
            status.done(f"{path}: {'error' if strict else 'warning'}: {log.fault}")
            if strict:
                return False
        elif not log.indexed:
            status.done(f"{path}: read through ({log.count} events)")
        for warning in log.warnings:
            print(f"{path}: warning: {warning}", file=sys.stderr)
    return True


def apply_selection(files: Any, ns: Any) -> list[str]:
    """The cut (--start/--end, seconds from the first event) and the topics left out
    (--topics, --exclude); warnings for patterns that match no topic."""
    from miro_gen.eventlog.types import matches

    first, _ = files.span()
    if ns.start:
        files.cut_front(first + int(ns.start * 1e9))
    if ns.end is not None:
        files.cut_back(first + int(ns.end * 1e9))
    names = [t.name for t in files.topics()]
    said = []
    for pattern in [*(ns.topics or []), *ns.exclude]:
        if not any(matches(pattern, *name) for name in names):
            said.append(f"warning: no topic matches {pattern[0]}/{pattern[1]}")
    for name in names:
        wanted = ns.topics is None or any(matches(p, *name) for p in ns.topics)
        if not wanted or any(matches(p, *name) for p in ns.exclude):
            files.exclude(name)
    return said


def channel_mode(ns: Any) -> str:
    return "shared" if ns.shared_channels else "unified" if ns.unified_channel else "own"


def play_main(argv: Sequence[str]) -> int:
    prog = "miro log play"
    p = argparse.ArgumentParser(
        prog=prog,
        description="Replay logs (several are merged in log-time order) into each robot's "
        "channel: every event at its log time (scaled by --rate), with its recorded domain, "
        "type, sequence number and source stamp. " + KEYS + " " + COMMON,
    )
    p.add_argument(
        "files",
        nargs="+",
        metavar="FILE",
        help="MCAP files written by miro log record, or rosbag2 files (played onto "
        "their ROS 2 topics)",
    )
    add_channel_options(p)
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    p.add_argument("--loop", action="store_true", help="start again at the end")
    add_selection_options(p)
    p.add_argument(
        "--wait",
        type=float,
        default=0.5,
        metavar="S",
        help="seconds to let consumers connect before the first event (default 0.5)",
    )
    p.add_argument(
        "--wait-subscribed",
        action="store_true",
        help="then wait until every topic played has a consumer on its channel (Miro's -a)",
    )
    p.add_argument(
        "--foxglove",
        nargs="?",
        const=f"127.0.0.1:{FOXGLOVE_PORT}",
        metavar="[ADDR:]PORT",
        help="also serve the replay to Foxglove or Lichtblick, whose playback controls then "
        f"drive it (default 127.0.0.1:{FOXGLOVE_PORT}; another address needs --insecure; "
        "the foxglove extra)",
    )
    ns = p.parse_args(split_common(p, argv))
    if not ns.rate > 0:
        p.error("--rate must be more than 0")
    check_selection(p, ns)
    from miro_gen.cli.log_ros2 import is_rosbag, play_ros2

    if is_rosbag(ns.files):  # onto ROS 2 topics, as ros2 bag play
        return play_ros2(prog, ns)
    if ns.foxglove is not None:
        from miro_gen.cli.foxglove import listen_at, sdk_missing

        ns.foxglove = listen_at(p, ns.foxglove, argv)
        if sdk_missing():
            return 1
    from miro_gen.eventlog.fileset import FileSet

    files = FileSet()
    try:
        if not open_files(ns.files, files, strict=True):
            return 1
        for line in apply_selection(files, ns):
            print(f"{prog}: {line}", file=sys.stderr)
        return _run(p, prog, argv, ns, files)
    finally:
        files.close()


def _run(p: argparse.ArgumentParser, prog: str, argv: Sequence[str], ns: Any, files: Any) -> int:
    from miro_gen.eventlog.keys import key_presses
    from miro_gen.eventlog.player import Player, pace_process
    from miro_gen.eventlog.progress import StatusLine, bar
    from miro_gen.eventlog.routes import ClockPublisher, Routes
    from miro_gen.exceptions import SystemException

    server = make_server(p, prog, argv)
    routes = Routes(server, ns.channel, channel_mode(ns))
    try:
        problems = routes.connect(files.domains())
        clock = ClockPublisher(server, ns.clock_channel)
    except SystemException as e:
        print(f"{prog}: {server.options.naming}: {e}", file=sys.stderr)
        server.close()
        return 1
    for line in problems:
        print(f"{prog}: warning: {line}", file=sys.stderr)
    if not routes.routes and files.domains():
        print(f"{prog}: error: no channel to play into", file=sys.stderr)
        server.close()
        return 1
    send: Callable[[Any], object] = routes.send
    publish_clock: Callable[[Any], object] = clock
    door = None
    if ns.foxglove is not None:
        from miro_gen.foxglove.bridge import BridgeError
        from miro_gen.foxglove.playback import PlaybackDoor

        try:
            door = PlaybackDoor(files, ns.foxglove)
        except BridgeError as e:  # the port is taken
            print(f"{prog}: {e}", file=sys.stderr)
            server.close()
            return 1
        send, publish_clock = _both(routes.send, door.send), _both(clock, door.clock)
        print(
            f"{prog}: serving the replay to Foxglove at ws://{ns.foxglove.address}:{door.port}",
            file=sys.stderr,
            flush=True,
        )
    reactor_thread = threading.Thread(target=server.run, name="miro-reactor", daemon=True)
    reactor_thread.start()
    player = Player(files, send, publish_clock, rate=ns.rate, loop=ns.loop)
    if door is not None:
        door.attach(player)
    status = StatusLine()
    shown = [0.0]

    def progress(force: bool = False) -> None:
        now = time.monotonic()
        if now - shown[0] < 0.1 and not force:
            return
        shown[0] = now
        start, end = files.cut
        span = max(1, end - start)
        at = player.log_now() - start
        state = " paused (space: resume, s: step)" if player.paused else ""
        pace = player.pace()  # a keep-all consumer holds it back: the rate it really plays at
        rate = f"x{player.rate:g}" if pace is None else f"x{pace:.2g} (held back, x{player.rate:g})"
        status.update(
            f"{bar(at / span)} {at / 1e9:8.2f}/{span / 1e9:.2f} s  {player.sent} events  "
            f"{rate}{state}"
        )

    quit_now = threading.Event()
    actions = {
        " ": player.toggle,
        "s": player.next,
        ".": player.next,
        "right": player.next,
        "p": player.prev,
        ",": player.prev,
        "left": player.prev,
        "shift-right": lambda: player.skip(1),
        "]": lambda: player.skip(1),
        "shift-left": lambda: player.skip(-1),
        "[": lambda: player.skip(-1),
        "+": lambda: player.faster(1),
        "=": lambda: player.faster(1),
        "-": lambda: player.faster(-1),
        "0": player.stop,
        "home": player.stop,
        "q": quit_now.set,
    }

    def on_key(key: str) -> None:
        action = actions.get(key if len(key) > 1 else key.lower())
        if action is not None:
            action()
        progress(force=True)

    signal.signal(signal.SIGTERM, lambda *_: quit_now.set())
    into = ", ".join(sorted({r.channel for r in routes.routes.values()}))
    print(f"playing {' '.join(ns.files)} into {into} at x{ns.rate:g}", file=sys.stderr)
    topics = [t.name for t in files.topics() if t.name not in files.excluded]
    topics = [t for t in topics if routes.channel_of(t[0]) is not None]
    try:
        quit_now.wait(max(0.0, ns.wait))
        if ns.wait_subscribed and not quit_now.is_set():
            _wait_subscribed(prog, routes, topics, quit_now)
        if not quit_now.is_set():  # (told to stop before it began: nothing is played)
            pace_process()  # a replayed event must leave on time
            player.start()
            player.play()
            with key_presses(on_key):
                while not quit_now.is_set() and not (player.ended.is_set() and not player.loop):
                    quit_now.wait(0.05)
                    progress()
    except KeyboardInterrupt:
        pass
    finally:
        player.close()
        time.sleep(0.2)  # let the last frames leave
        if door is not None:
            door.close()
        server.shutdown()
        reactor_thread.join(5)
    names = " ".join(ns.files)
    status.done(f"{names}: replayed {player.sent} events into {into}")
    if player.error is not None:
        where = getattr(player.error, "path", prog)
        print(f"{where}: error: {player.error}", file=sys.stderr)
        return 1
    return 0


def _wait_subscribed(
    prog: str, routes: Routes, topics: list[tuple[str, str]], quit_now: threading.Event
) -> None:
    """Wait until every topic played has a consumer (or `quit_now`), saying which have none
    (again whenever that changes: a consumer that subscribes to some topics only, or that
    goes away, would otherwise leave the replay waiting without a word)."""
    said: list[str] = []
    while not quit_now.is_set():
        missing = [f"{d}/{t}" for d, t in topics if not routes.subscribed(d, t)]
        if not missing:
            return
        if missing != said:
            more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
            shown = ", ".join(missing[:5]) + more
            print(f"{prog}: waiting for a consumer of {shown}", file=sys.stderr, flush=True)
            said = missing
        quit_now.wait(0.02)


def _both(first: Callable[[Any], object], second: Callable[[Any], object]) -> Callable[[Any], None]:
    """One callback that calls `first`, then `second`."""

    def call(value: Any) -> None:
        first(value)
        second(value)

    return call
