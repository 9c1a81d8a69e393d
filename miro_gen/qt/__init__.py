"""Qt integration (the manual's chapter 11): events into a Qt GUI safely, polled calls that do
not freeze it, and Qt Designer forms bound to topics and calls at run time.

    bridge = QtEventBridge(Server(sys.argv), window=window)
    sub = bridge.subscribe([("*", "Imu")], channel="EventChannel")  # latest-only per topic
    sub.received.connect(window.show_imu)  # runs on the GUI thread
    bridge.start()

Needs PySide6, which the optional extra installs: `pip install miro-gen[qt]`.
"""

from __future__ import annotations

try:
    import PySide6.QtCore
    import PySide6.QtWidgets  # noqa: F401 - only to fail here, with the remedy
except ImportError as _e:
    raise ImportError(
        f"miro_gen.qt needs PySide6, which cannot be imported ({_e}): pip install miro-gen[qt]"
    ) from _e

from miro_gen.qt.bridge import Mailbox, QtEventBridge, Subscription
from miro_gen.qt.calls import CallRunner, PendingCall

__all__ = ["CallRunner", "Mailbox", "PendingCall", "QtEventBridge", "Subscription"]
