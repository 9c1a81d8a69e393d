"""Zero-copy decoding: while `octet_views()` is active on a thread, sequences of octets decoded
there from a read-only memoryview (runtime.cdr.get_octets) are read-only memoryviews of it, not
`bytes` copies. A consumer reading large events in shared memory uses it (transport.events:
`zero_copy`); the views are valid only as long as the memory under them is."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

active = threading.local()  # `on`: views instead of copies, on this thread


@contextmanager
def octet_views() -> Iterator[None]:
    """Decode sequences of octets as views while the block runs (on this thread)."""
    active.on = True
    try:
        yield
    finally:
        active.on = False
