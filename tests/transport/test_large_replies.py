"""Large call replies between real processes: the reply body is decoded from a view over the
received frame (issue 29), and what the stub returns is still what the contract promises."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import Miro
import pytest
import zmq
from procs.camera_server import pattern
from repo_paths import TESTS

from miro_gen.runtime.cdr import ObjectRef
from miro_gen.runtime.views import octet_views
from miro_gen.transport.rpc.frames import ZERO_COPY_MIN
from miro_gen.transport.rpc.invoker import ZmqInvoker

SIZES = [ZERO_COPY_MIN - 100, ZERO_COPY_MIN, 1 << 20]  # below and above the view's threshold


@pytest.fixture(params=SIZES, ids=lambda n: f"{n}B")
def camera(request: pytest.FixtureRequest) -> Iterator[tuple[Miro.Camera, int]]:
    size: int = request.param
    proc = subprocess.Popen(
        [sys.executable, str(TESTS / "procs" / "camera_server.py"), str(size)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    line = proc.stdout.readline().split()
    assert line and line[0] == "READY", f"server did not start: {line}"
    invoker = ZmqInvoker(zmq.Context())
    try:
        yield Miro.Camera(ObjectRef("IDL:Miro/Camera:1.0", line[1], b"Camera"), invoker), size
    finally:
        invoker.close()
        invoker.context.term()
        proc.kill()
        proc.wait(10)


def test_a_large_reply_is_bytes_with_every_byte_in_place(camera: tuple[Miro.Camera, int]) -> None:
    stub, size = camera
    for frame in (4, 5, 6):
        image = stub.getWaitImage()
        assert type(image.data) is bytes
        assert image.data == pattern(size)
        assert (image.frame, image.time, image.format.width) == (frame, Miro.TimeIDL(1, 2), size)


def test_views_of_a_reply_stay_valid_and_read_only(camera: tuple[Miro.Camera, int]) -> None:
    """Under octet_views() the octets of a large reply are a read-only view of the frame it came
    in, which stays valid after later calls (the view keeps the frame); a small one is bytes."""
    stub, size = camera
    with octet_views():
        first = stub.getImage().data
        for _ in range(3):
            stub.getImage()
    if size < ZERO_COPY_MIN:
        assert type(first) is bytes
    else:
        assert isinstance(first, memoryview) and first.readonly
        with pytest.raises(TypeError):
            first[0] = 1  # type: ignore[index]
    assert bytes(first) == pattern(size)
