"""The checkout's generated code comes first on the path, including what the wheel leaves out
(the manual's example parameters, package Test)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zmq

GENERATED = str(Path(__file__).resolve().parents[1] / "generated")
if GENERATED not in sys.path:
    sys.path.insert(0, GENERATED)


@pytest.fixture(scope="module")
def naming() -> Iterator[str]:
    """The endpoint of a `miro naming` process shared by a test module."""
    from loopback import NamingProcess

    process = NamingProcess()
    yield process.endpoint
    process.stop()


@pytest.fixture
def servers(naming: str) -> Iterator[Callable[[str], Any]]:
    """Makes Servers (`servers(naming_context)`) whose reactors run in threads of the test;
    stopped after it."""
    from loopback import RunningServer

    started: list[RunningServer] = []

    def make(context: str) -> Any:
        r = RunningServer(naming, context)
        started.append(r)
        return r.server

    yield make
    for r in reversed(started):
        r.stop()


@pytest.fixture
def reactor() -> Iterator[object]:
    """A Reactor running in a thread of its own; closed, with its context, after the test."""
    from miro_gen.transport.reactor import Reactor

    r = Reactor(zmq.Context())
    thread = r.run_in_thread()
    yield r
    r.stop()
    thread.join(5)
    assert not thread.is_alive(), "the reactor did not stop"
    r.close()
    r.context.term()
