"""The allocator of a process that moves large messages: buffers up to `MMAP_BELOW` come from
the heap and freed ones stay there, instead of glibc's default of mapping each megabyte buffer
afresh and returning it when freed.

Every large message takes new buffers of its size (ZeroMQ's, the body's `bytes`, an encoder's);
with glibc's defaults each new one of a megabyte is faulted in page by page and trimmed again
when freed. Measured: the Foxglove bridge's CPU per 1 MB event fell from about 2.5 ms to 1.2 ms
(1 MB events at 150/s, load about 6); a caller's 1 MiB reply (bench_rpc.py --sizes, bench/
README.md). The transport sets it in a process once it sends or receives a call body of
`rpc.frames.ZERO_COPY_MIN` or more, the bridge when it starts. The cost: up to `TRIM_ABOVE`
bytes of freed heap are kept for the next messages.
"""

from __future__ import annotations

import threading

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameters (malloc.h)
M_MMAP_THRESHOLD = -3
MMAP_BELOW = 32 << 20  # glibc's largest mmap threshold on 64-bit (HEAP_MAX_SIZE / 2)
TRIM_ABOVE = 256 << 20

_done = threading.Lock()
_state: list[bool] = []


def keep_large_buffers() -> bool:
    """Set this process's allocator for large messages, once; False where the C library has
    no `mallopt` (not glibc) or refuses the values."""
    if _state:  # the common case once set: no lock
        return _state[0]
    with _done:
        if not _state:
            _state.append(_tune())
        return _state[0]


def _tune() -> bool:
    import ctypes  # here: ctypes.util brings subprocess and tempfile, which a process that
    import ctypes.util  # never moves a large message does not need at start

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    # Setting either one fixes both (glibc stops adjusting them to what was freed).
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_BELOW)) and bool(
        mallopt(M_TRIM_THRESHOLD, TRIM_ABOVE)
    )
