"""The camera service: images from a V4L2 device, a video file or a network stream, through OpenCV,
published as Miro::ImageEventIDL events and served by Miro::Camera.

    python services/camera [-MCF robot.xml] [--device DEV|FILE|URL] [common options]
    miro run camera [...]                  (the same, from an installed miro-gen)
    miro sim camera --http 8090 &  python services/camera --device http://127.0.0.1:8090/

Needs OpenCV: `pip install 'miro-gen[camera]'` (opencv-python-headless). Its parameters
(services/camera/CameraParameters.xml, compiled into Miro.CameraParameters: device, size, rate,
encoding, JPEG quality, looping a file, names, getWaitImage's timeout) come from the run-time
document, section "Camera", category "Camera"; `--device` overrides it.

The pieces: `FrameSource` (services/camera/capture.py), a thread that opens the source (again
when it fails or goes away), keeps to the rate and turns each frame into an ImageEventIDL;
`CameraImpl`, the runtime's `Implementation` base: `getImage` returns the latest image,
`getWaitImage` the next, `getFormat` their size and layout, and every image is published. On exit
it prints how many frames it read, skipped and published.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from miro_gen.lifecycle import defer_signals, run_main

if __name__ == "__main__":
    defer_signals()  # first: a Ctrl-C while it starts ends it quietly (status 130)
if __package__ in (None, ""):  # run as a script (python services/camera): the generated code
    _here = Path(__file__).resolve().parent  # beside the checkout, and this folder as the
    sys.path[:0] = [str(_here.parents[1] / "generated"), str(_here.parent)]  # package it is
    __package__ = _here.name  # (as `python -m services.camera` and `miro run camera` import it)

import Miro
import Miro__POA
from Miro.CameraParameters import CameraParameters
from miro_gen import (
    Implementation,
    StructuredPushSupplier,
    log,
    nonblocking,
)
from miro_gen.devices import SubscriberNotice, startup

_log = log.logger("Camera")


class CameraImpl(Miro__POA.Camera, Implementation[Miro.ImageEventIDL]):
    """Miro::Camera: the latest image, the next one, their format."""

    def __init__(self, supplier: StructuredPushSupplier | None, params: CameraParameters) -> None:
        Implementation.__init__(
            self,
            supplier,
            params.eventName,
            initial=Miro.ImageEventIDL(),
            timeout=params.waitTimeout.total_seconds(),
        )
        self.format = Miro.ImageFormatIDL()

    @nonblocking
    def getFormat(self) -> Miro.ImageFormatIDL:
        return self.format

    @nonblocking
    def getImage(self) -> Miro.ImageEventIDL:
        return self.latest()

    def getWaitImage(self) -> Miro.ImageEventIDL:
        return self.wait_next(Miro.ETimeOut)

    def integrate_image(self, image: Miro.ImageEventIDL, stamp: float) -> None:
        self.format = image.format
        self.integrate_data(image, stamp)


def options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", help="V4L2 device or number, video file or URL (overrides)")


def main(argv: list[str] | None = None) -> int:
    server, args = startup.start("camera", argv, __doc__, options)
    try:
        from .capture import FrameSource
    except ImportError as e:
        startup.fail("camera", f"needs OpenCV ({e}): pip install 'miro-gen[camera]'")
    params = CameraParameters.instance()
    startup.read(params, "Camera", server, "camera")
    if args.device:
        params.device = args.device
    _log.debug("parameters:\n%s", params)
    supplier = startup.supplier_on(server, params.channelName, "camera")
    impl = CameraImpl(supplier, params)
    try:
        source = FrameSource(params, impl.integrate_image)
    except ValueError as e:
        startup.fail("camera", e)
    impl.format = source.format
    subscribers = SubscriberNotice(supplier, params.eventName, "images")
    server.add_to_name_service(impl, params.objectName)
    server.reactor().schedule_timer(0.25, 0.25, lambda _: subscribers.check())
    source.start()
    print(
        f"camera: reading {params.device}, serving {params.objectName}, "
        f"publishing {params.eventName} on {params.channelName}",
        flush=True,
    )
    server.on_shutdown(source.stop)
    server.run()
    source.stop()
    print(
        f"camera: {source.read} frames read, {source.skipped} skipped for the rate, "
        f"{source.frames} images, {impl.published} published, {supplier.dropped} dropped "
        f"at the channel; opened {source.opened} times",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    run_main(main, "camera")
