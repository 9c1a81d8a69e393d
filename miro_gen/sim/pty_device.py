"""A pseudo-terminal that plays a serial device: the simulator writes to its master side, the
driver opens the slave side like any serial port."""

from __future__ import annotations

import contextlib
import errno
import os
import select
import tty
from pathlib import Path


class PtyDevice:
    """A pseudo-terminal, reachable at `path` (the slave's own name, or `link` when given: a
    stable name that survives `vanish()` and `appear()`, as a udev rule gives a USB adapter)."""

    def __init__(self, link: Path | None = None) -> None:
        self.link = link
        self.dropped = 0  # bytes written while nobody read and the terminal's buffer was full
        self.master = -1
        self._slave = -1
        self.appear()

    @property
    def path(self) -> str:
        return str(self.link) if self.link else os.ttyname(self._slave)

    def appear(self) -> None:
        """Create the terminal (again), and point the link at it."""
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # bytes pass unchanged, even before the driver configures it
        os.set_blocking(self.master, False)
        if self.link:
            fresh = self.link.with_name(self.link.name + ".new")
            fresh.unlink(missing_ok=True)
            fresh.symlink_to(os.ttyname(self._slave))
            fresh.replace(self.link)

    def vanish(self) -> None:
        """Remove the terminal, as when a USB adapter is pulled: the driver's reads fail."""
        if self.link:
            self.link.unlink(missing_ok=True)
        for fd in (self._slave, self.master):
            with contextlib.suppress(OSError):
                os.close(fd)
        self.master = self._slave = -1

    def write(self, data: bytes, wait: float = 0.0) -> None:
        """Send bytes as the device would. What the terminal cannot take is dropped (and
        counted), at once or, with `wait`, after waiting that long for the reader to make
        room: a device does not wait, a replay that must lose nothing does."""
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.master, view) :]
            except OSError as e:
                if e.errno not in (errno.EAGAIN, errno.EIO, errno.EBADF):  # EBADF: vanished
                    raise
                if e.errno == errno.EAGAIN and select.select([], [self.master], [], wait)[1]:
                    continue
                self.dropped += len(view)
                return

    def read(self, n: int, timeout: float = 5.0) -> bytes:
        """Up to `n` bytes the driver wrote (commands to the device), waiting at most `timeout`."""
        out = b""
        while len(out) < n and select.select([self.master], [], [], timeout)[0]:
            out += os.read(self.master, n - len(out))
        return out

    def close(self) -> None:
        self.vanish()
