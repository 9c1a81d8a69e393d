"""Images in event payloads (miro_gen.qt.images) and the event viewer showing them, offscreen:
Miro::ImageEventIDL in each encoding, a ROS-like struct, and what is not an image."""

from __future__ import annotations

import dataclasses
import importlib.util
from collections.abc import Iterator

import Miro
import pytest
import zmq
from qt_procs import REPO
from qt_support import QImage, application, qt_wait

from miro_gen import Server, StructuredEvent
from miro_gen.qt import QtEventBridge
from miro_gen.qt.images import ImageField, find_image, to_qimage

E = Miro.ImageEncodingIDL
RED, GREEN, BLUE = (255, 0, 0), (0, 255, 0), (0, 0, 255)


def camera_image(
    encoding: Miro.ImageEncodingIDL, data: bytes, width: int, height: int, step: int
) -> Miro.ImageEventIDL:
    form = Miro.ImageFormatIDL(width, height, encoding, step)
    return Miro.ImageEventIDL(Miro.TimeIDL(1, 2), 7, form, data)


def rgb(image: QImage, x: int, y: int) -> tuple[int, int, int]:
    c = image.pixelColor(x, y)
    return c.red(), c.green(), c.blue()


def test_a_camera_image_in_each_raw_encoding() -> None:
    # 2x2, rows padded to 8 bytes: red, green / blue, white
    rows = bytes([*RED, *GREEN, 0, 0]) + bytes([*BLUE, 255, 255, 255, 0, 0])
    found = find_image(camera_image(E.IMAGE_RGB8, rows, 2, 2, 8))
    assert found == ImageField("data", rows, 2, 2, "rgb8", 8)
    image = to_qimage(found)
    assert image is not None and (image.width(), image.height()) == (2, 2)
    assert [rgb(image, 0, 0), rgb(image, 1, 0), rgb(image, 0, 1)] == [RED, GREEN, BLUE]
    bgr = to_qimage(find_image(camera_image(E.IMAGE_BGR8, rows, 2, 2, 8)))  # type: ignore[arg-type]
    assert bgr is not None and rgb(bgr, 0, 0) == BLUE and rgb(bgr, 0, 1) == RED
    mono = find_image(camera_image(E.IMAGE_MONO8, bytes([0, 100, 200, 255]), 2, 2, 2))
    assert mono is not None and mono.encoding == "mono8"
    grey = to_qimage(mono)
    assert grey is not None and rgb(grey, 1, 0) == (100, 100, 100)


def test_compressed_images_are_told_by_their_bytes() -> None:
    source = QImage(4, 3, QImage.Format.Format_RGB888)
    source.fill(0x00FF00)
    buffer = _png(source)
    found = find_image(camera_image(E.IMAGE_PNG, buffer, 4, 3, 0))
    assert found is not None and found.encoding == "png"
    image = to_qimage(found)
    assert image is not None and image.size() == source.size() and rgb(image, 3, 2) == GREEN
    mislabelled = find_image(camera_image(E.IMAGE_RGB8, buffer, 4, 3, 12))
    assert mislabelled is not None and mislabelled.encoding == "png"


def _png(image: QImage) -> bytes:
    from PySide6.QtCore import QBuffer, QIODevice

    buffer = QBuffer()
    buffer.open(QIODevice.OpenModeFlag.WriteOnly)
    assert image.save(buffer, "PNG")
    return bytes(buffer.data().data())


@dataclasses.dataclass
class RosImage:
    height: int
    width: int
    encoding: str
    step: int
    data: bytes


@dataclasses.dataclass
class Stamped:
    seq: int
    image: RosImage


def test_any_struct_with_pixels_and_a_size() -> None:
    pixels = bytes([*RED, *BLUE])
    found = find_image(Stamped(1, RosImage(1, 2, "bgr8", 6, pixels)))
    assert found == ImageField("image.data", pixels, 2, 1, "bgr8", 6)
    unnamed = find_image(RosImage(2, 2, "", 0, bytes(4)))  # 1 byte a pixel: grey
    assert unnamed is not None and (unnamed.encoding, unnamed.step) == ("mono8", 2)
    assert to_qimage(unnamed) is not None


def test_what_is_not_an_image() -> None:
    assert find_image(Miro.ExampleEventIDL()) is None
    assert find_image(RosImage(0, 0, "rgb8", 0, b"")) is None  # no size
    short = find_image(RosImage(2, 2, "rgb8", 6, bytes(11)))
    assert short is not None and to_qimage(short) is None  # fewer bytes than it says
    assert to_qimage(ImageField("data", b"not a png", 2, 2, "png", 0)) is None
    assert to_qimage(ImageField("data", bytes(4), 2, 2, "yuv422", 4)) is None


@pytest.fixture
def viewer(naming: str) -> Iterator[object]:
    spec = importlib.util.spec_from_file_location("event_viewer", REPO / "services/event_viewer.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    application()
    server = Server(["viewer", "--naming", naming], context=zmq.Context())
    window = module.ViewerWindow(QtEventBridge(server), "Image")
    window.show()
    yield window
    window.close()


def test_the_viewer_shows_an_image_field_as_an_image(viewer: object) -> None:
    window: object = viewer
    assert not window.image.isVisible()  # type: ignore[attr-defined]
    width, height = 64, 48
    red = bytes(RED) * (width * height)
    payload = camera_image(E.IMAGE_RGB8, red, width, height, 192)
    event = StructuredEvent("cam", "Image", payload, 1, 1.0, 1.0)
    window.show_event(event)  # type: ignore[attr-defined]
    view = window.image  # type: ignore[attr-defined]
    qt_wait(view.isVisible)
    assert view.image is not None and (view.image.width(), view.image.height()) == (64, 48)
    assert view.caption == "data: 64x48 rgb8"
    shot = view.grab().toImage()
    assert rgb(shot, shot.width() // 2, shot.height() // 2) == RED
    assert window.fields.value_text("data") == f"{len(red)} bytes"  # type: ignore[attr-defined]
