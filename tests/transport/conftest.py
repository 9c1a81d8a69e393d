"""Fixtures of the transport tests: a ZeroMQ invoker that may use shared memory (the
shared-memory call and request tests'; a module that needs another defines its own)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import zmq

from miro_gen.transport.rpc.invoker import ZmqInvoker


@pytest.fixture
def invoker(monkeypatch: pytest.MonkeyPatch) -> Iterator[ZmqInvoker]:
    """A caller with shared memory on (MIRO_SHM=1), closed after the test."""
    monkeypatch.setenv("MIRO_SHM", "1")
    invoker = ZmqInvoker(zmq.Context())
    yield invoker
    invoker.close()
    invoker.context.term()
