"""A camera for `miro sim camera` and the camera service's tests: synthetic frames that carry their
own number, written to a video file or served as an MJPEG stream over HTTP (as IP cameras do).

Each frame shows a bright disc circling over a colour gradient, and its number in a bar code:
two rows of 16 cells at the top left, white for 1, black for 0, 24 bits of the number then 8
bits of check, each cell 1/80 of the image's width, so that `frame_number()` reads it back from
a decoded JPEG, at another size too. Needs OpenCV (`pip install 'miro-gen[camera]'`).
"""

from __future__ import annotations

import http.server
import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

CELLS = 32  # bits in the bar code: 24 of number, 8 of check
BOUNDARY = b"miroframe"

Image = Any  # a numpy array of height x width x 3 bytes (BGR), as OpenCV has them


def _check(number: int) -> int:
    return (number ^ (number >> 8) ^ (number >> 16) ^ 0xA5) & 0xFF


def _cells(width: int) -> Iterator[tuple[int, int, int]]:
    """(x, y, size) of each bar-code cell, in pixels."""
    size = width / 80
    for k in range(CELLS):
        yield round(size * (1 + k % 16)), round(size * (1 + k // 16)), max(1, round(size))


def synthetic_frame(number: int, width: int, height: int) -> Image:
    """Frame `number` of the synthetic video (BGR)."""
    x = np.linspace(0, 255, width, dtype=np.uint8)
    y = np.linspace(0, 255, height, dtype=np.uint8)
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:, :, 0] = x[None, :]
    image[:, :, 1] = y[:, None]
    image[:, :, 2] = (number * 4) % 256
    angle = number * 2 * math.pi / 90
    centre = (
        int(width / 2 + width / 4 * math.cos(angle)),
        int(height / 2 + height / 4 * math.sin(angle)),
    )
    cv2.circle(image, centre, max(2, height // 10), (255, 255, 255), -1)
    bits = ((number & 0xFFFFFF) << 8) | _check(number & 0xFFFFFF)
    for k, (cx, cy, size) in enumerate(_cells(width)):
        value = 255 if bits >> (CELLS - 1 - k) & 1 else 0
        image[cy : cy + size, cx : cx + size] = value
    return image


def frame_number(image: Image) -> int | None:
    """The number a synthetic frame carries (BGR, or grey), or None if it carries none."""
    width = image.shape[1]
    bits = 0
    for cx, cy, size in _cells(width):
        inset = size // 4
        cell = image[cy + inset : cy + size - inset, cx + inset : cx + size - inset]
        bits = bits << 1 | int(cell.mean() > 127)
    number = bits >> 8
    return number if bits & 0xFF == _check(number) else None


def write_video(path: Path, frames: int, width: int, height: int, rate: float) -> None:
    """`frames` synthetic frames at `rate` a second, as Motion JPEG in `path` (.avi), or MPEG-4
    Part 2 (.mp4)."""
    fourcc = cv2.VideoWriter.fourcc(*("mp4v" if path.suffix == ".mp4" else "MJPG"))
    writer = cv2.VideoWriter(str(path), fourcc, rate, (width, height))
    if not writer.isOpened():
        raise OSError(f"{path}: OpenCV cannot write this kind of video")
    try:
        for n in range(frames):
            writer.write(synthetic_frame(n, width, height))
    finally:
        writer.release()


class MjpegStream:
    """An HTTP server on `port` (0: any) sending the synthetic video to every client that GETs
    any path, as `multipart/x-mixed-replace` JPEG parts at `rate` a second, each client from frame
    0. `sent` counts the frames sent."""

    def __init__(
        self, width: int, height: int, rate: float, port: int = 0, quality: int = 90
    ) -> None:
        stream = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                stream._serve(self)

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self.width, self.height, self.rate, self.quality = width, height, rate, quality
        self.sent = 0
        self.stopping = threading.Event()
        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        self.url = f"http://127.0.0.1:{self.port}/video.mjpg"

    def _serve(self, request: http.server.BaseHTTPRequestHandler) -> None:
        request.send_response(200)
        request.send_header(
            "Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY.decode()}"
        )
        request.end_headers()
        start = time.monotonic()
        n = 0
        params = [cv2.IMWRITE_JPEG_QUALITY, self.quality]
        while not self.stopping.is_set():
            _, jpeg = cv2.imencode(".jpg", synthetic_frame(n, self.width, self.height), params)
            data = jpeg.tobytes()
            part = b"--%s\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % (
                BOUNDARY,
                len(data),
            )
            try:
                request.wfile.write(part + data + b"\r\n")
                request.wfile.flush()
            except OSError:  # the client left
                return
            self.sent += 1
            n += 1
            time.sleep(max(0.0, start + n / self.rate - time.monotonic()))

    def serve(self) -> threading.Thread:
        thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        self.stopping.set()
        self.server.shutdown()
        self.server.server_close()
