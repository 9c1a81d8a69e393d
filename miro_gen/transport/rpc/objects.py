"""The objects a process serves, by key: the table an object adapter of either backbone (ZeroMQ's
ROUTER socket, Zenoh's queryable) looks a request's object up in, and hands references out of."""

from __future__ import annotations

import itertools
import os
import threading

from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.rpc import Servant


class ObjectTable:
    """Servants by key; references name them at `endpoint`, which the adapter sets once it
    knows where it listens. Keys made here are unique to this process (`PID.N`)."""

    endpoint: str

    def __init__(self) -> None:
        self._servants: dict[bytes, Servant] = {}
        self._keys = itertools.count(1)
        self._prefix = f"{os.getpid()}.".encode()
        self._table_lock = threading.Lock()

    def activate(self, servant: Servant, key: bytes | None = None) -> ObjectRef:
        """Serve `servant` under `key` (a fresh one by default); its reference."""
        with self._table_lock:
            if key is None:
                key = self._prefix + str(next(self._keys)).encode()
            self._servants[key] = servant
        return ObjectRef(servant._repo_id, self.endpoint, key)

    def deactivate(self, key: bytes) -> None:
        with self._table_lock:
            self._servants.pop(key, None)

    def servants(self) -> list[tuple[bytes, Servant]]:
        """(key, servant) of every object served here."""
        with self._table_lock:
            return list(self._servants.items())

    def reference_for(self, servant: Servant) -> ObjectRef:
        """The reference of a servant, activating it on first use."""
        with self._table_lock:
            for key, s in self._servants.items():
                if s is servant:
                    return ObjectRef(servant._repo_id, self.endpoint, key)
        return self.activate(servant)

    def servant(self, key: bytes) -> Servant | None:
        """The servant served under `key`, if any (from any thread)."""
        return self._servants.get(key)
