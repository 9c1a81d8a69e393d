"""Large events (megabytes: camera images, point clouds) through event channels over real
sockets: they arrive whole and in order among small ones, in the host's own process through
its in-process endpoints too."""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable

import Miro
import zmq
from loopback import Recorder, eventually

from miro_gen import EventChannelFactory, Server, StructuredPushSupplier
from miro_gen.transport.local import nearest


def cloud(n: int, floats: int) -> Miro.Range3dScanEventIDL:
    """A scan whose intensities are `floats` numbers that say which scan they belong to."""
    values = array("f", range(floats))
    values[0] = n
    return Miro.Range3dScanEventIDL(Miro.TimeIDL(n, 0), intensity=values)


def test_megabyte_events_arrive_whole_and_in_order_among_small_ones(
    servers: Callable[[str], Server],
) -> None:
    host = servers("r")
    channel = EventChannelFactory(host).create_channel("Clouds")
    supplier = StructuredPushSupplier(channel)
    remote = Recorder(servers("c").resolve_channel("r/Clouds"))
    local = Recorder(channel)  # in the host's process: the in-process endpoint
    assert channel.endpoints(host.context)[1].startswith("inproc://")
    elsewhere = channel.endpoints(zmq.Context())[1]  # another process on this host: ipc://
    assert elsewhere == nearest(channel.consumer_endpoint) != channel.consumer_endpoint
    for c in (remote, local):
        c.set_subscriptions([("*", "*")])
    eventually(lambda: len(supplier._subscriptions) >= 1)
    time.sleep(0.3)
    # floats: 40 B ... 3 MB; large after large is encoded into its frame directly
    sizes = [10, 1 << 18, 5, 3 << 18, 1, 1, 1 << 16, 1 << 17, 1 << 14, 2]
    for n, floats in enumerate(sizes):
        supplier.push("Cloud", cloud(n, floats))
    for c in (remote, local):
        eventually(lambda c=c: len(c.events) == len(sizes), 30)  # type: ignore[misc]
        got = [e.payload for e in c.events]
        assert [p.time.sec for p in got] == list(range(len(sizes)))
        assert [len(p.intensity) for p in got] == sizes
        assert all(p.intensity[1:] == array("f", range(1, len(p.intensity))) for p in got)
        assert [e.seq for e in c.events] == list(range(len(sizes))) and c.missed == 0
    assert supplier.dropped == 0


def test_a_camera_image_as_a_call_result(naming: str, servers: Callable[[str], Server]) -> None:
    """6 MB through the ROUTER: a servant's result, sent without a copy."""
    import Miro__POA

    from miro_gen import Client

    image = Miro.ImageEventIDL(
        Miro.TimeIDL(1, 2),
        3,
        Miro.ImageFormatIDL(1280, 1600, Miro.IMAGE_RGB8, 3840),
        bytes(range(256)) * (3840 * 1600 // 256),
    )

    class Camera(Miro__POA.Camera):
        def getFormat(self) -> Miro.ImageFormatIDL:
            return image.format

        def getImage(self) -> Miro.ImageEventIDL:
            return image

        def getWaitImage(self) -> Miro.ImageEventIDL:
            return image

    servers("r").add_to_name_service(Camera(), "Camera")
    client = Client(["t", "--naming", naming])
    try:
        camera = client.resolve_name("r/Camera", Miro.Camera)
        assert camera.getImage() == image
        assert camera.getWaitImage().data == image.data
    finally:
        client.close()
