"""Fixtures of the replay tests: a naming service of their own and the player's server,
running on a thread (a module that needs another naming service defines its own)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest
import zmq
from loopback import NamingProcess

from miro_gen.service.server import Server


@pytest.fixture
def naming() -> Iterator[str]:
    process = NamingProcess()
    yield process.endpoint
    process.stop()


@pytest.fixture
def server(naming: str) -> Iterator[Server]:
    s = Server(["replay-test", "--naming", naming, "-MNC", "player"], context=zmq.Context())
    thread = threading.Thread(target=s.run, daemon=True)
    thread.start()
    yield s
    s.shutdown()
    thread.join(10)
