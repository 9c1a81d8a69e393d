"""A Qt Designer form as a Miro GUI (the manual's §11.1, with no generated code): loads a
`.ui` file at run time and binds its widgets to events and polled calls by object name.

    python services/qt_panel.py [FORM.ui] [--channel NAME] [--domain D] [--import MODULE]...
        [--screenshot FILE [--after N]] [--duration S] [common options]

FORM defaults to services/example_panel.ui (ExampleC's events, ExampleA's calls). The naming
rules for widgets are in miro_gen/qt/designer.py and docs/QT.md.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script from a checkout: the generated code beside it
    sys.path[:0] = [str(Path(__file__).resolve().parents[1] / "generated")]

import Miro  # noqa: F401 - the project's types and stubs, for decoding and calling
import MiroNaming
from miro_gen import Server, SystemException
from miro_gen.service.options import service_parser

try:
    from miro_gen.qt import QtEventBridge
    from miro_gen.qt.app import application, no_display
    from miro_gen.qt.designer import FormBinding, UiError, load_ui
    from PySide6.QtCore import QTimer
except ImportError as e:  # PySide6 missing (or a system library Qt needs)
    hint = "" if "miro-gen[qt]" in str(e) else ": pip install miro-gen[qt]"
    print(f"qt_panel: {e}{hint}", file=sys.stderr)
    sys.exit(1)

FORM = Path(__file__).resolve().with_name("example_panel.ui")


def main(argv: list[str] | None = None) -> int:
    server = Server(sys.argv if argv is None else argv)  # takes the common options out
    p = service_parser("qt_panel", __doc__.split("\n\n")[0])
    p.add_argument("form", nargs="?", type=Path, default=FORM, help="a Qt Designer .ui file")
    p.add_argument("--channel", default="ExampleEventChannel", help="the event channel")
    p.add_argument("--domain", default="*", help="the suppliers' naming context (default any)")
    p.add_argument("--import", dest="imports", action="append", default=[], metavar="MODULE")
    p.add_argument("--screenshot", type=Path, help="save the window as PNG, then quit")
    p.add_argument("--after", type=int, default=10, help="events shown before --screenshot")
    p.add_argument("--duration", type=float, help="quit after this many seconds")
    args = p.parse_args(server.argv[1:])
    for module in args.imports:
        try:
            importlib.import_module(module)
        except ImportError as e:
            p.error(f"cannot import {module}: {e}")
    problem = no_display()
    if problem is not None:
        print(f"qt_panel: {problem}", file=sys.stderr)
        return 1
    app = application("qt_panel")
    try:
        form = load_ui(args.form)
        bridge = QtEventBridge(server, window=form)
        binding = FormBinding(form, bridge, channel=args.channel, domain=args.domain)
        binding.source = str(args.form)
        binding.bind()
    except UiError as e:
        print(f"qt_panel: {e}", file=sys.stderr)
        return 1
    except MiroNaming.NotFound as e:
        print(f"qt_panel: {e.name} is not bound: start its supplier first", file=sys.stderr)
        return 1
    except SystemException as e:  # the naming service is unreachable, ...
        print(f"qt_panel: {e}", file=sys.stderr)
        return 1
    shown = [0]

    def screenshot() -> None:
        if args.screenshot is not None and not form.grab().save(str(args.screenshot), "PNG"):
            print(f"qt_panel: cannot write {args.screenshot}", file=sys.stderr)
        app.quit()

    def count(_: object) -> None:
        shown[0] += 1
        if shown[0] == args.after and args.screenshot is not None:
            QTimer.singleShot(50, screenshot)

    for sub in bridge.subscriptions:
        sub.received.connect(count)
    if args.duration is not None:
        QTimer.singleShot(int(args.duration * 1000), screenshot)
    form.show()
    bridge.start()
    app.exec()
    bridge.stop()
    print(f"qt_panel: {shown[0]} events shown", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "qt_panel")
