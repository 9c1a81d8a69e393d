"""Images inside event payloads, for the viewers: where the pixels are and how to show them.

An image field is a struct with a `bytes` field (the pixels, or a compressed file) and, in the
struct or in a struct it holds, the image's `width` and `height` (or `cols`, `rows`), and
optionally its `encoding` (an enum or a string: mono8, rgb8, bgr8, rgba8, bgra8, jpeg, png, with
or without a prefix such as `IMAGE_`) and `step` (bytes a row). Miro::ImageEventIDL is one
(`format.width`, `format.encoding`, `data`); so is a ROS-like `{width, height, encoding, step,
data}`. Without an encoding it is told from the data: a JPEG or PNG file by its first bytes,
else one, three or four bytes a pixel.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

from PySide6.QtGui import QImage

from miro_gen.qt.fields import field_names

# Raw encodings: bytes a pixel and the QImage format of rows in that layout.
_RAW = {
    "mono8": (1, QImage.Format.Format_Grayscale8),
    "rgb8": (3, QImage.Format.Format_RGB888),
    "bgr8": (3, QImage.Format.Format_BGR888),
    "rgba8": (4, QImage.Format.Format_RGBA8888),
    "bgra8": (4, QImage.Format.Format_ARGB32),  # B, G, R, A in memory on little-endian hosts
}
_COMPRESSED = {"jpeg", "jpg", "png"}
_MAGIC = {b"\xff\xd8\xff": "jpeg", b"\x89PNG": "png"}
_WIDTH = ("width", "cols")
_HEIGHT = ("height", "rows")
_ENCODING = ("encoding", "pixel_format", "format")
_STEP = ("step", "stride", "row_bytes")
_MAX_DEPTH = 3  # structs searched below the payload


@dataclass(frozen=True)
class ImageField:
    """An image found in a payload: the path of its bytes, its size and layout."""

    path: str
    data: bytes
    width: int
    height: int
    encoding: str  # one of _RAW's or _COMPRESSED's names, or "" when unknown
    step: int  # bytes a row (raw encodings)


def find_image(payload: Any) -> ImageField | None:
    """The first image field in `payload` (the payload itself, or a struct inside it)."""
    return _search(payload, "", 0)


def _search(value: Any, path: str, depth: int) -> ImageField | None:
    names = field_names(value)
    if not names:
        return None
    image = _image_of(value, names, path)
    if image is not None or depth >= _MAX_DEPTH:
        return image
    for name in names:
        found = _search(getattr(value, name), _join(path, name), depth + 1)
        if found is not None:
            return found
    return None


def _image_of(value: Any, names: list[str], path: str) -> ImageField | None:
    """The image of struct `value` when it has the pixels and (it or a member) the size."""
    data_name = next((n for n in names if isinstance(getattr(value, n), bytes)), None)
    if data_name is None:
        return None
    data: bytes = getattr(value, data_name)
    places = [value, *(getattr(value, n) for n in names if field_names(getattr(value, n)))]
    width, height = _number(places, _WIDTH), _number(places, _HEIGHT)
    if not width or not height:
        return None
    encoding = _encoding(_member(places, _ENCODING), data, width * height)
    pixel = _RAW[encoding][0] if encoding in _RAW else 0
    step = _number(places, _STEP) or width * pixel
    return ImageField(_join(path, data_name), data, width, height, encoding, step)


def _member(places: list[Any], names: tuple[str, ...]) -> Any:
    """The value of the first of `names` (any case) that a place has and that is no struct."""
    for wanted in names:
        for place in places:
            for name in field_names(place):
                value = getattr(place, name)
                if name.lower() == wanted and not field_names(value):
                    return value
    return None


def _number(places: list[Any], names: tuple[str, ...]) -> int:
    value = _member(places, names)
    return value if isinstance(value, int) and not isinstance(value, bool) else 0


def _encoding(value: Any, data: bytes, pixels: int) -> str:
    """The normalised name of an encoding field's value, or the one the data shows."""
    for magic, name in _MAGIC.items():
        if data.startswith(magic):
            return name
    text = value.name if isinstance(value, enum.Enum) else value if isinstance(value, str) else ""
    text = text.lower()
    for name in (*_RAW, *_COMPRESSED):
        if text == name or text.endswith("_" + name):
            return "jpeg" if name == "jpg" else name
    by_size = {pixels: "mono8", 3 * pixels: "rgb8", 4 * pixels: "rgba8"}
    return by_size.get(len(data), "")


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def to_qimage(image: ImageField) -> QImage | None:
    """The image as a QImage (its own copy of the pixels), or None if the data does not hold
    the image its fields describe."""
    if image.encoding in _COMPRESSED:
        decoded = QImage.fromData(image.data)
        return None if decoded.isNull() else decoded
    raw = _RAW.get(image.encoding)
    if raw is None or image.step < image.width * raw[0]:
        return None
    if len(image.data) < image.step * image.height:
        return None
    view = QImage(image.data, image.width, image.height, image.step, raw[1])
    return view.copy()  # the QImage must not outlive the payload's bytes
